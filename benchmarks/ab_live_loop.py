"""A/B of the live loop between two revisions: alternating rounds, paired differences.

Why: on this shared 2-core machine one run of bench_live_loop.py varies far more than the
changes it should judge (session 15: the same code ran the three-process state loop at 168-391
steps/s and the in-process loop at 540-1006 in one hour). A change worth 10 % shows only as a
difference paired within rounds, the order of the two sides flipped every round so neither
always runs first. Each side runs its own bench_live_loop.py from a git worktree of its
revision (`--new` defaults to the working tree), with its own `zeus_ros` first on PYTHONPATH;
the message package is the installed one, so the revisions must agree on `msg_defs/`.

    source scripts/env.sh && python benchmarks/ab_live_loop.py --base 3f30c92 --new 968ed43 \
        --rounds 10 --modes multi --steps 2000 [--out ab.csv]

Prints, per observation kind and mode, each metric's mean on both sides and the paired
difference new - base as mean ± standard error over the rounds.
"""

from __future__ import annotations

import argparse
import csv
import os
from pathlib import Path
import re
import statistics
import subprocess
import sys
import tempfile

REPO = Path(__file__).resolve().parents[1]
ROW = re.compile(r'^(?P<kind>state|pixels)\s+(?P<mode>\S+)\s+(?P<executor>\S+)\s+'
                 r'(?P<in_process>[\d.]+)\s+(?P<live>[\d.]+)\s+(?P<ratio>[\d.]+)\s+\[[^\]]*\]!?\s+'
                 r'[\d.]+/(?P<cpu_ms>[\d.na]+)\s+\S+\s+(?P<p50>[\d.na]+)\s+(?P<p99>[\d.na]+)')
"""One result line of bench_live_loop.py (its table has kept this shape since session 8).

Each side runs its own bench_live_loop.py: against a base from before session 17 the p50/p99
differ in ruler too (the base times them at the probe, the new side from the publishers'
source timestamps), so compare their latencies only between revisions on the same side of it.
"""
METRICS = ('live', 'ratio', 'cpu_ms', 'p50', 'p99', 'in_process')


def parse_rows(text: str) -> list[dict[str, str | float]]:
    """The result rows of one bench_live_loop.py run (ValueError when there are none)."""
    rows: list[dict[str, str | float]] = []
    for line in text.splitlines():
        match = ROW.match(line)
        if match:
            row: dict[str, str | float] = dict(match.groupdict())
            for key in METRICS:
                row[key] = float(row[key])
            rows.append(row)
    if not rows:
        raise ValueError(f'no result line in the benchmark output:\n{text[-2000:]}')
    return rows


def worktree(rev: str, path: Path) -> Path:
    """A detached worktree of `rev` at `path` (removed by `remove_worktree`).

    Named by side, not by revision: the same revision on both sides is an A/A run, which
    measures the noise alone.
    """
    subprocess.run(['git', '-C', str(REPO), 'worktree', 'add', '--detach', '-q', str(path), rev],
                   check=True)
    return path


def remove_worktree(path: Path) -> None:
    subprocess.run(['git', '-C', str(REPO), 'worktree', 'remove', '--force', str(path)],
                   check=False)


def run_side(tree: Path, bench_args: list[str]) -> list[dict[str, str | float]]:
    """One bench_live_loop.py run from `tree`, its zeus_ros first on the path."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(tree), env.get('PYTHONPATH', '')])
    done = subprocess.run([sys.executable, str(tree / 'benchmarks' / 'bench_live_loop.py'),
                           *bench_args], env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f'bench_live_loop.py in {tree} exited {done.returncode}:\n'
                           f'{(done.stdout + done.stderr)[-3000:]}')
    return parse_rows(done.stdout)


def summary(results: list[dict[str, str | float]]) -> list[str]:
    """Per kind and mode: each metric's means and the paired difference new - base."""
    lines = []
    keys = sorted({(r['kind'], r['mode']) for r in results})
    for kind, mode in keys:
        rounds = sorted({int(r['round']) for r in results
                         if (r['kind'], r['mode']) == (kind, mode)})
        by = {(int(r['round']), r['side']): r for r in results
              if (r['kind'], r['mode']) == (kind, mode)}
        paired = [n for n in rounds if (n, 'base') in by and (n, 'new') in by]
        lines.append(f'{kind} {mode}: {len(paired)} paired rounds')
        for metric in METRICS:
            base = [float(by[n, 'base'][metric]) for n in paired]
            new = [float(by[n, 'new'][metric]) for n in paired]
            diffs = [b - a for a, b in zip(base, new, strict=True)]
            error = statistics.stdev(diffs) / len(diffs) ** 0.5 if len(diffs) > 1 else float('nan')
            lines.append(f'  {metric:<10} base {statistics.mean(base):9.3f}  new '
                         f'{statistics.mean(new):9.3f}  new - base {statistics.mean(diffs):+9.3f}'
                         f' ± {error:.3f}')
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--base', required=True, help='revision to compare against')
    parser.add_argument('--new', default='', help='revision to judge (default: the working tree)')
    parser.add_argument('--rounds', type=int, default=6)
    parser.add_argument('--kinds', default='state')
    parser.add_argument('--modes', default='multi')
    parser.add_argument('--steps', type=int, default=2000)
    parser.add_argument('--pixel-steps', type=int, default=120)
    parser.add_argument('--out', type=Path, help='CSV of every run (round, side, metrics)')
    args = parser.parse_args()
    if args.rounds < 2:
        parser.error('--rounds must be at least 2 (a standard error needs two differences)')
    bench_args = ['--kinds', args.kinds, '--modes', args.modes, '--steps', str(args.steps),
                  '--pixel-steps', str(args.pixel_steps)]
    results: list[dict[str, str | float]] = []
    with tempfile.TemporaryDirectory(prefix='zeus_ab_') as tmp:
        trees = {'base': worktree(args.base, Path(tmp) / 'base')}
        trees['new'] = worktree(args.new, Path(tmp) / 'new') if args.new else REPO
        try:
            for number in range(1, args.rounds + 1):
                order = ('base', 'new') if number % 2 else ('new', 'base')
                for side in order:
                    for row in run_side(trees[side], bench_args):
                        results.append({'round': number, 'side': side, **row})
                        print(f'round {number:>2} {side:<4} {row["kind"]} {row["mode"]}: '
                              f'{row["live"]:.1f} steps/s, CPU {row["cpu_ms"]:.2f} ms/step, '
                              f'p99 {row["p99"]:.2f} ms', flush=True)
        finally:
            for tree in trees.values():
                if tree != REPO:
                    remove_worktree(tree)
    if args.out:
        with args.out.open('w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=list(results[0]))
            writer.writeheader()
            writer.writerows(results)
    print(f'base {args.base} against new {args.new or "(working tree)"}, order flipped each '
          'round; paired difference new - base: mean ± standard error over rounds')
    print('\n'.join(summary(results)))


if __name__ == '__main__':
    main()
