"""Does a faster Adam make the update cheaper? Per-tensor loop vs foreach vs fused, side by side.

Issue 10 asked for a cheaper update (fused Adam, fewer optimizers). This measures it instead of
assuming it: three copies of the same agent (state CPU config, Cheetah-Run-v0 shapes from the
synthetic system) differ only in torch's Adam implementation, and are timed in interleaved
blocks of updates so that machine load hits all three alike. The table gives the median and
the best block, and each implementation's median relative to the per-tensor loop. Usage:

    python benchmarks/bench_optimizers.py [--methods zeus no_context] [--blocks 8] [--block 20]
"""

from __future__ import annotations

import argparse
from pathlib import Path
import statistics
import time

import torch
from tqdm import tqdm

from zeus_ros.learning import load_config, make_agent
from zeus_ros.learning.agent import ZeusAgent
from zeus_ros.learning.synthetic import SyntheticSystem
from zeus_ros.offline.evaluation.metrics import format_table

REPO = Path(__file__).resolve().parents[1]
TASK = 'Cheetah-Run-v0'
IMPLEMENTATIONS = {'loop': {'foreach': False}, 'foreach': {'foreach': True},
                   'fused': {'fused': True}}


def with_adam(agent: ZeusAgent, **implementation: bool) -> ZeusAgent:
    """Rebuild the agent's Adam optimizers with the same groups and another implementation."""
    for name, opt in agent.optimizers.items():
        groups = [{k: v for k, v in group.items() if k not in ('foreach', 'fused')}
                  for group in opt.param_groups]
        agent.optimizers[name] = torch.optim.Adam(groups, **implementation)
    return agent


def compare(method: str, blocks: int, block: int) -> list[dict[str, object]]:
    """Median and best ms per update of each implementation, interleaved block by block."""
    config = load_config(REPO / 'params/train/state_cpu.yaml').replace(method=method,
                                                                        device='cpu')
    system = SyntheticSystem(obs_dim=17, action_dim=6, k=config.k, pixels=False)
    agents = {name: with_adam(make_agent(config, system.spec(TASK)), **kwargs)
              for name, kwargs in IMPLEMENTATIONS.items()}
    batches = [system.sample(config.batch_size) for _ in range(4)]
    for agent in agents.values():  # warm-up: allocator, autograd, optimizer state
        for step in range(3):
            agent.update(batches[0], batches[1], step)
    ms: dict[str, list[float]] = {name: [] for name in agents}
    for _ in tqdm(range(blocks), desc=method, leave=False):
        for name, agent in agents.items():
            start = time.perf_counter()
            for step in range(block):
                agent.update(batches[step % 4], batches[(step + 1) % 4], step)
            ms[name].append(1000 * (time.perf_counter() - start) / block)
    base = statistics.median(ms['loop'])
    return [{'method': method, 'adam': name, 'ms_median': statistics.median(times),
             'ms_best': min(times), 'vs_loop': statistics.median(times) / base}
            for name, times in ms.items()]


def main() -> None:
    """Measure every method and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--methods', nargs='+', default=['zeus', 'no_context'])
    parser.add_argument('--blocks', type=int, default=8)
    parser.add_argument('--block', type=int, default=20, help='updates per timed block')
    parser.add_argument('--threads', type=int, default=1, help='torch CPU threads')
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    rows = [row for method in args.methods for row in compare(method, args.blocks, args.block)]
    print(f'Adam implementations, ms per update ({TASK} shapes, state_cpu.yaml, '
          f'torch threads={args.threads})')
    print(format_table(rows, ['method', 'adam', 'ms_median', 'ms_best', 'vs_loop']))


if __name__ == '__main__':
    main()
