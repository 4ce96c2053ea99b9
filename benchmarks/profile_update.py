"""Where an update's time goes: torch.profiler over n updates per method, 1 thread.

Same agents and batches as bench_update_ratio.py (params/train/state_cpu.yaml, synthetic
Cheetah-Run-v0 shapes). Prints each method's top ops by self CPU time (--shapes: grouped by
input shape, which tells the encoder's history pass from the critic's). Usage:

    python benchmarks/profile_update.py [--methods zeus no_context] [--updates 50] [--shapes]
"""

from __future__ import annotations

import argparse

from bench_update_ratio import updater  # benchmarks/ is on the path: run as a script
import torch
from torch.profiler import ProfilerActivity, profile


def main() -> None:
    """Profile each method's updates and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--methods', nargs='+', default=['zeus', 'no_context'])
    parser.add_argument('--updates', type=int, default=50)
    parser.add_argument('--rows', type=int, default=25)
    parser.add_argument('--shapes', action='store_true', help='group by input shape')
    args = parser.parse_args()
    torch.set_num_threads(1)
    for method in args.methods:
        run = updater(method)
        with profile(activities=[ProfilerActivity.CPU], record_shapes=args.shapes) as prof:
            run(args.updates)
        print(f'== {method}: {args.updates} updates')
        print(prof.key_averages(group_by_input_shape=args.shapes).table(
            sort_by='self_cpu_time_total', row_limit=args.rows))


if __name__ == '__main__':
    main()
