"""Where an ingest's time goes: cProfile over n ingests of one bag, next to its plain read.

Writes the bench's bag (bench_ingest.write_bag) unless --bags names existing ones, then prints
the plain read's and the ingest's CPU seconds and the ingest's top functions by own time.
Usage:

    python benchmarks/profile_ingest.py --pixels --storage mcap [--steps 2000] [--repeat 10]
    python benchmarks/profile_ingest.py --bags data/bags --sort cumulative
"""

from __future__ import annotations

import argparse
import cProfile
from pathlib import Path
import pstats
import tempfile
import time

from bench_ingest import plain_read, write_bag  # benchmarks/ is on the path: run as a script

from zeus_ros.bags.recording import find_bags
from zeus_ros.offline.data.ingest import ingest_bags


def main() -> None:
    """Profile `repeat` ingests of one bag and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bags', type=Path, help='existing bags (else a temporary one)')
    parser.add_argument('--steps', type=int, default=2_000)
    parser.add_argument('--pixels', action='store_true')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap')
    parser.add_argument('--repeat', type=int, default=10)
    parser.add_argument('--rows', type=int, default=25)
    parser.add_argument('--sort', default='tottime', help='a pstats sort key')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = args.bags or Path(tmp) / 'bag'
        if args.bags is None:
            write_bag(root, args.steps, pixels=args.pixels, storage=args.storage)
        paths = find_bags(root)
        plain_read(paths)  # warm the page cache
        cpu = time.process_time()
        for _ in range(args.repeat):
            plain_read(paths)
        plain = (time.process_time() - cpu) / args.repeat
        ingest_bags(paths)  # warm imports and the codec's caches
        profiler = cProfile.Profile()
        cpu = time.process_time()
        profiler.enable()
        for _ in range(args.repeat):
            ingest_bags(paths)
        profiler.disable()
        ingest = (time.process_time() - cpu) / args.repeat
    print(f'CPU s per read: plain {plain:.4f}, ingest {ingest:.4f} (profiled): '
          f'ratio {plain / ingest:.2f}')
    pstats.Stats(profiler).sort_stats(args.sort).print_stats(args.rows)


if __name__ == '__main__':
    main()
