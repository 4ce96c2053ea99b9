"""Ingest throughput next to a plain rosbags read of the same files, in the same run.

The plain read iterates every raw message with rosbags' Reader without deserializing: the
floor any ingest pays. Without arguments, every case issue 14 names (a state bag in mcap, a
pixel bag in mcap and in sqlite3) is written, measured and summed up, each ratio within its own
case. Usage:

    python benchmarks/bench_ingest.py                    # the three cases, temporary bags
    python benchmarks/bench_ingest.py --pixels --steps 2000 --storage sqlite3   # one case
    python benchmarks/bench_ingest.py --bags data/bags   # existing bags
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
import tempfile
import time

import numpy as np
from rosbags.rosbag2 import Reader

from zeus_ros.bags.recording import find_bags
from zeus_ros.bags.schema import StepFeedbackFields
from zeus_ros.bags.writer import SimStep, StepBagWriter
from zeus_ros.offline.data.ingest import ingest_bags

EP_LEN = 500
INGEST_TARGET = 0.5
"""Issue 14: ingest at least half as fast as a plain read of the same files."""
STATE_DIM = 17
ACTION_DIM = 6


def write_bag(path: Path, steps: int, *, pixels: bool, storage: str) -> None:
    """A cheetah-shaped bag (17-d state, 6-d action, 84x84 frames) from random arrays."""
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, (84, 84, 3), np.uint8)
    with StepBagWriter(path, storage=storage, pixels=pixels) as writer:
        for k in range(steps):
            ep, es = divmod(k, EP_LEN + 1)
            stamp = (k + 1) * 40_000_000
            fb = StepFeedbackFields(
                episode=ep, episode_step=es, first=es == 0, last=es == EP_LEN,
                reward=float(rng.random()),
                applied_action=np.zeros(0) if es == 0 else rng.random(ACTION_DIM),
                action_status=0 if es == 0 else 1, task='Cheetah-Run-v0')
            writer.write_step(SimStep(
                step=k, stamp_ns=stamp, state=rng.random(STATE_DIM), feedback=fb,
                context_names=('torso_length',), context_values=np.array([0.5 + ep % 3]),
                segment=ep, frame=np.roll(frame, k, axis=1) if pixels else None))
            writer.write_action(k, stamp, rng.random(ACTION_DIM))


def plain_read(paths: list[Path]) -> tuple[float, int]:
    """Seconds to iterate every raw message of `paths`, and the payload bytes seen."""
    start = time.perf_counter()
    total = 0
    for path in paths:
        with Reader(path) as reader:
            for _, _, raw in reader.messages():
                total += len(raw)
    return time.perf_counter() - start, total


def disk_bytes(paths: list[Path]) -> int:
    """Bytes on disk of the bags' files."""
    files = [p for path in paths for p in ([path] if path.is_file() else path.iterdir())]
    return sum(f.stat().st_size for f in files if f.is_file())


DEFAULT_CASES: tuple[tuple[str, int, bool, str], ...] = (
    ('state mcap', 20_000, False, 'mcap'),
    ('pixel mcap', 2_000, True, 'mcap'),
    ('pixel sqlite3', 2_000, True, 'sqlite3'),
)
"""(name, steps, pixels, storage) of the default run: every ratio issue 14 names."""


def measure(paths: list[Path], repeat: int) -> tuple[float, float]:
    """Print plain-read and ingest MB/s and CPU seconds (best of `repeat`); their two ratios.

    The two contenders alternate (plain, ingest, plain, ...), so a burst of load on a busy
    machine falls on both alike instead of skewing one side.
    """
    size_mb = disk_bytes(paths) / 1e6
    plain_read(paths)  # warm the page cache for both contenders
    plain_s, plain_cpu, ingest_cpu = math.inf, math.inf, math.inf
    best = None
    for _ in range(repeat):
        cpu = time.process_time()
        plain_s = min(plain_s, plain_read(paths)[0])
        plain_cpu = min(plain_cpu, time.process_time() - cpu)
        cpu = time.process_time()
        ds = ingest_bags(paths)
        ingest_cpu = min(ingest_cpu, time.process_time() - cpu)
        if best is None or ds.report.seconds < best.report.seconds:
            best = ds
    assert best is not None
    rep = best.report
    print(f'bags: {len(paths)}, {size_mb:.1f} MB on disk, {rep.steps} steps, '
          f'{rep.messages} messages')
    print(f'plain read : {size_mb / plain_s:8.1f} MB/s  ({plain_s:.3f} s)')
    print(f'ingest     : {rep.mb_per_s:8.1f} MB/s  ({rep.seconds:.3f} s, '
          f'{rep.steps_per_s:.0f} steps/s)')
    ratio = rep.mb_per_s / (size_mb / plain_s)
    print(f'ratio ingest/plain: {ratio:.2f} [target {INGEST_TARGET}]' + _unmet(ratio))
    # CPU seconds: what the wall clock shows on an idle machine, steadier under load.
    cpu_ratio = plain_cpu / ingest_cpu
    print(f'CPU s plain {plain_cpu:.3f} / ingest {ingest_cpu:.3f}: ratio {cpu_ratio:.2f} '
          f'[target {INGEST_TARGET}]' + _unmet(cpu_ratio))
    return ratio, cpu_ratio


def _unmet(ratio: float) -> str:
    return '' if ratio >= INGEST_TARGET else ' (not met)'


def main() -> None:
    """Measure the default cases, or the one case the arguments name, and print the ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bags', type=Path, help='existing bags (else temporary ones)')
    parser.add_argument('--steps', type=int, help='steps of the temporary bag (one case)')
    parser.add_argument('--pixels', action='store_true', help='a pixel bag (one case)')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3'), help='its storage (one case)')
    parser.add_argument('--repeat', type=int, default=5)
    args = parser.parse_args()
    if args.bags is not None:
        measure(find_bags(args.bags), args.repeat)
        return
    one_case = args.steps is not None or args.pixels or args.storage is not None
    cases = [('', args.steps or (2_000 if args.pixels else 20_000), args.pixels,
              args.storage or 'mcap')] if one_case else DEFAULT_CASES
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, steps, pixels, storage) in enumerate(cases):
            if name:
                print(f'== {name}')
            root = Path(tmp) / f'bag_{i}'
            t0 = time.perf_counter()
            write_bag(root, steps, pixels=pixels, storage=storage)
            print(f'wrote {steps} steps (pixels={pixels}, {storage}) '
                  f'in {time.perf_counter() - t0:.2f} s')
            results.append((name, *measure(find_bags(root), args.repeat)))
    if len(results) > 1:
        print(f'ingest/plain, wall / CPU [target {INGEST_TARGET}; ! not met]: ' + ', '.join(
            f'{name} {ratio:.2f}{"!" * (ratio < INGEST_TARGET)} / {cpu:.2f}'
            f'{"!" * (cpu < INGEST_TARGET)}' for name, ratio, cpu in results))


if __name__ == '__main__':
    main()
