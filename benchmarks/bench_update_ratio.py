"""Issue 51's first target: a ZeUS update >= 0.6x a no_context update (CPU), 1 thread.

Both agents are built from params/train/state_cpu.yaml (Cheetah-Run-v0 shapes from the synthetic
system, pre-sampled batches cycled, as bench_updates.py), and timed in alternating blocks in one
process, so a noisy shared machine slows both alike. Ratio = no_context time / ZeUS time per
block pair (higher is better; 1.0 would be free context learning); the median of the repeats is
printed beside the target, for CPU time (time.process_time) and wall time. Usage:

    python benchmarks/bench_update_ratio.py [--updates 50] [--repeats 3] [--threads 1]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
import statistics
import time

import torch

from zeus_ros.learning import load_config, make_agent
from zeus_ros.learning.synthetic import SyntheticSystem

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / 'params/train/state_cpu.yaml'
TARGET = 0.6
"""Issue 51: ZeUS update >= 0.6x a no_context update, CPU time."""


def updater(method: str, warmup: int = 3) -> Callable[[int], None]:
    """A function running n updates of a fresh `method` agent (warmed up, batches cycled)."""
    config = load_config(CONFIG).replace(method=method, device='cpu')
    system = SyntheticSystem(obs_dim=17, action_dim=6, k=config.k)
    agent = make_agent(config, system.spec('Cheetah-Run-v0'))
    batches = [system.sample(config.batch_size) for _ in range(4)]
    step = 0

    def run(n: int) -> None:
        nonlocal step
        for _ in range(n):
            agent.update(batches[step % 4], batches[(step + 1) % 4], step)
            step += 1

    run(warmup)
    return run


def timed(run: Callable[[int], None], n: int) -> tuple[float, float]:
    """(CPU seconds, wall seconds) of n updates."""
    cpu, wall = time.process_time(), time.perf_counter()
    run(n)
    return time.process_time() - cpu, time.perf_counter() - wall


def main() -> None:
    """Alternate ZeUS and no_context blocks; print per-update costs and the median ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--updates', type=int, default=50, help='updates per block')
    parser.add_argument('--repeats', type=int, default=3, help='block pairs (median reported)')
    parser.add_argument('--threads', type=int, default=1, help='torch CPU threads')
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    zeus, plain = updater('zeus'), updater('no_context')
    cpu_ratios, wall_ratios = [], []
    for repeat in range(args.repeats):
        order = [('zeus', zeus), ('no_context', plain)]
        if repeat % 2:
            order.reverse()
        costs = {name: timed(run, args.updates) for name, run in order}
        (z_cpu, z_wall), (p_cpu, p_wall) = costs['zeus'], costs['no_context']
        cpu_ratios.append(p_cpu / z_cpu)
        wall_ratios.append(p_wall / z_wall)
        ms = 1000 / args.updates
        print(f'repeat {repeat}: zeus {z_cpu * ms:.2f} ms CPU ({z_wall * ms:.2f} wall), '
              f'no_context {p_cpu * ms:.2f} ms CPU ({p_wall * ms:.2f} wall), '
              f'ratio {cpu_ratios[-1]:.2f} CPU ({wall_ratios[-1]:.2f} wall)')
    cpu, wall = statistics.median(cpu_ratios), statistics.median(wall_ratios)
    verdict = 'met' if cpu >= TARGET else 'not met'
    print(f'ZeUS update / no_context update ({CONFIG.name}, {args.threads} thread(s), median of '
          f'{args.repeats}): {cpu:.2f} CPU (wall {wall:.2f}); target >= {TARGET} CPU: {verdict}')


if __name__ == '__main__':
    main()
