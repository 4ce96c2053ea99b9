"""Agent updates per second: the pixel (paper) config next to the CPU state config, one run.

Both agents get Cheetah-Run-v0 shapes (17-d state or 3 stacked 84x84 RGB frames, 6-d action)
from the synthetic system, and a few pre-sampled batches are cycled, so the numbers are the cost
of `ZeusAgent.update` alone (sampling from bags is benchmarked by bench_ingest.py). The pixel
config gets few updates: each takes seconds on a CPU. `--pixel-configs` measures other pixel
configs in the same run, NAME[:UPDATES] under params/train/ (route (b) of issue 36: the paper's
pixel config next to pixels_cpu.yaml). Usage:

    python benchmarks/bench_updates.py [--state-updates 200] [--pixel-updates 3] [--threads 1]
    python benchmarks/bench_updates.py --methods zeus --no-state \
        --pixel-configs pixels_paper.yaml:3 pixels_cpu.yaml:20
"""

from __future__ import annotations

import argparse
from pathlib import Path
import time

import torch
from tqdm import tqdm

from zeus_ros.learning import load_config, make_agent
from zeus_ros.learning.synthetic import SyntheticSystem
from zeus_ros.offline.evaluation.metrics import format_table

REPO = Path(__file__).resolve().parents[1]
TASK = 'Cheetah-Run-v0'


def updates_per_second(config_path: Path, *, pixels: bool, updates: int, method: str,
                       device: str, warmup: int = 2) -> dict[str, object]:
    """Time `updates` updates after `warmup` untimed ones (allocator and autograd warm-up)."""
    config = load_config(config_path).replace(method=method, device=device)
    system = SyntheticSystem(obs_dim=17, action_dim=6, k=config.k, pixels=pixels)
    agent = make_agent(config, system.spec(TASK))
    batches = [system.sample(config.batch_size) for _ in range(4)]
    for step in range(warmup):
        agent.update(batches[0], batches[1], step)
    if agent.device.type == 'cuda':
        torch.cuda.synchronize()
    start = time.perf_counter()
    for step in tqdm(range(updates), desc=f'{config_path.stem} {method}', leave=False):
        agent.update(batches[step % 4], batches[(step + 1) % 4], warmup + step)
    if agent.device.type == 'cuda':
        torch.cuda.synchronize()
    seconds = time.perf_counter() - start
    return {'config': config_path.name, 'method': method, 'obs': 'pixels' if pixels else 'state',
            'device': str(agent.device), 'batch': config.batch_size,
            'encoder': f'{config.num_conv_layers}x{config.num_filters}',
            'hidden': config.hidden_dim, 'shift': config.augment_shift, 'updates': updates,
            'updates_per_s': updates / seconds, 'ms_per_update': 1000 * seconds / updates}


def main() -> None:
    """Measure both configs and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--state-updates', type=int, default=200)
    parser.add_argument('--pixel-updates', type=int, default=3)
    parser.add_argument('--methods', nargs='+', default=['zeus', 'no_context'])
    parser.add_argument('--device', default='cpu', help='cpu, cuda, auto')
    parser.add_argument('--threads', type=int, default=1, help='torch CPU threads')
    parser.add_argument('--pixel-configs', nargs='+', default=['pixels_paper.yaml'],
                        metavar='NAME[:UPDATES]',
                        help='pixel configs under params/train/ (default: pixels_paper.yaml), '
                        'each with its own update count (default --pixel-updates)')
    parser.add_argument('--no-state', action='store_true', help='skip the state config')
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    pixel_runs = [(name.partition(':')[0], int(name.partition(':')[2] or args.pixel_updates))
                  for name in args.pixel_configs]
    rows = []
    for method in args.methods:
        if not args.no_state:
            rows.append(updates_per_second(REPO / 'params/train/state_cpu.yaml', pixels=False,
                                           updates=args.state_updates, method=method,
                                           device=args.device))
        for name, updates in pixel_runs:
            rows.append(updates_per_second(REPO / 'params/train' / name, pixels=True,
                                           updates=updates, method=method, device=args.device))
    print(f'update throughput ({TASK} shapes, torch threads={args.threads})')
    print(format_table(rows, ['config', 'method', 'obs', 'device', 'batch', 'encoder', 'hidden',
                              'shift', 'updates', 'updates_per_s', 'ms_per_update']))


if __name__ == '__main__':
    main()
