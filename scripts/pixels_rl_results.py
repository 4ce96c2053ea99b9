r"""docs/results/pixels/rl_cpu/: route (b) of issue 36, pixel RL on this CPU, beside the student.

    python scripts/pixels_rl_results.py --run runs/pixels_rl_cpu/s0 \
        --log runs/pixels_rl_cpu/s0.log --eval runs/pixels_rl_cpu/eval_all \
        --student-eval runs/pixels_student/eval_all \
        --student-rounds runs/pixels_student/student_s*/rounds.csv

Reads the 60-minute `zeus loop` run (its timestamped log: rounds, collections, the periodic
evaluations on the train values; run/metrics.csv: updates and their rate), the `zeus eval
--split all` tables of its checkpoint and of the distilled students, and the students' DAgger
rounds (collect_s + train_s: their wall time per seed). Writes table.md, rl_cpu.csv (one row per
checkpoint and split), eval_over_time.csv and return_vs_wall.png into --out. Why a script: the
numbers in docs/results/pixels/README.md come from files, not from a reading of logs by hand.
"""

from __future__ import annotations

import argparse
import csv
import glob
from pathlib import Path
import re

import numpy as np

OUT = Path(__file__).resolve().parents[1] / 'docs' / 'results' / 'pixels' / 'rl_cpu'
SPLITS = ('train', 'interpolation', 'extrapolation')


def _read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline='') as handle:
        return list(csv.DictReader(handle))


def _summary(folder: Path) -> dict[str, dict[str, str]]:
    """The summary.csv row per split of the one task folder under a `zeus eval` --out."""
    paths = sorted(folder.glob('*/summary.csv'))
    if not paths:
        raise SystemExit(f'{folder}: no */summary.csv (run zeus eval --split all first)')
    return {row['split']: row for row in _read_csv(paths[0])}


def _log(path: Path) -> dict[str, object]:
    """Wall times from the run's timestamped log (`<epoch> <line>` per line)."""
    start = end = None
    evals: list[tuple[float, int, float]] = []
    collected: list[tuple[int, float]] = []
    stopped = None
    for line in path.read_text().splitlines():
        stamp, _, text = line.partition(' ')
        if not stamp.isdigit():
            continue
        now = float(stamp)
        start = now if start is None else start
        end = now
        if match := re.match(r'eval @ (\d+): mean return (-?[\d.]+)', text):
            evals.append((now - start, int(match[1]), float(match[2])))
        if match := re.match(r'train: interrupted at update (\d+)', text):
            stopped = int(match[1])
        if match := re.match(r'loop: wrote (\d+) steps .* in ([\d.]+) s', text):
            collected.append((int(match[1]), float(match[2])))
    return {'wall_s': (end or 0.0) - (start or 0.0), 'evals': evals, 'collected': collected,
            'stopped': stopped}


def _fmt(value: str | float | None, se: str | float | None = None) -> str:
    if value in (None, ''):
        return '-'
    text = f'{float(value):.1f}'
    return text if se in (None, '') else f'{text} ± {float(se):.1f}'


def main() -> None:
    """Read the runs and write the table, the CSVs and the figure."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--run', type=Path, required=True, help='the zeus loop --out')
    parser.add_argument('--log', type=Path, required=True, help="the loop's timestamped log")
    parser.add_argument('--eval', type=Path, required=True, help='zeus eval --out of its ckpt')
    parser.add_argument('--student-eval', type=Path, required=True,
                        help='zeus eval --out of the distilled students')
    parser.add_argument('--student-rounds', required=True, help='glob of their rounds.csv')
    parser.add_argument('--out', type=Path, default=OUT)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    log = _log(args.log)
    metrics = _read_csv(args.run / 'run' / 'metrics.csv')
    logged, train_s = int(float(metrics[-1]['step'])), float(metrics[-1]['time_s'])
    updates = log['stopped'] or logged  # the budget's SIGTERM saved the checkpoint there
    rates = [float(r['updates_per_s']) for r in metrics if r.get('updates_per_s')]
    env_steps = sum(steps for steps, _ in log['collected'])
    collect_s = sum(seconds for _, seconds in log['collected'])
    rl, student = _summary(args.eval), _summary(args.student_eval)
    student_wall = []
    for path in sorted(glob.glob(args.student_rounds)):
        rows = _read_csv(Path(path))
        student_wall.append(sum(float(r['collect_s']) + float(r['train_s']) for r in rows))

    rows = []
    for name, summary in (('pixel RL, pixels_cpu.yaml (60 min)', rl),
                          ('distilled pixel student', student)):
        for split in SPLITS:
            row = summary[split]
            rows.append({'checkpoint': name, 'split': split, 'seeds': row['seeds'],
                         'return': row['mean_return'], 'return_se': row['mean_return_se'],
                         'switching_return': row['switching_return'],
                         'spearman': row['spearman'], 'random_return': row['random_return']})
    with (args.out / 'rl_cpu.csv').open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    with (args.out / 'eval_over_time.csv').open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(['wall_s', 'update', 'mean_return_train_values'])
        writer.writerows(log['evals'])

    def split_cells(summary: dict[str, dict[str, str]]) -> str:
        return ' | '.join(_fmt(summary[s]['mean_return'], summary[s]['mean_return_se']
                               if int(summary[s]['seeds']) > 1 else None) for s in SPLITS)

    wall = np.array(student_wall) / 60
    lines = [
        '| route | seeds | wall time per seed | updates | env steps (rendered) | updates/s '
        '| return train | return interpolation | return beyond range |',
        '|---|---|---|---|---|---|---|---|---|',
        f'| (b) pixel RL, `pixels_cpu.yaml` | 1 | {log["wall_s"] / 60:.0f} min (budget) | '
        f'{updates:,} | {env_steps:,} | {logged / train_s:.2f} while training '
        f'({min(rates):.2f}-{max(rates):.2f} per log window); {updates / log["wall_s"]:.2f} '
        f'over the wall time | {split_cells(rl)} |',
        f'| (a) distilled student (`zeus distill`) | {len(student_wall)} | '
        f'{wall.min():.0f}-{wall.max():.0f} min | 2,400 (regression) | 4,000 teacher + 2,400 '
        f'student | - | {split_cells(student)} |',
        '| uniform random policy | - | - | - | - | - | '
        + ' | '.join(_fmt(rl[s]['random_return']) for s in SPLITS) + ' |',
        '',
        f'RL wall time: {train_s / 60:.1f} min of updates (to update {logged:,}), '
        f'{collect_s / 60:.1f} min of collection (rendered), the rest ingesting bags, '
        'evaluating and checkpointing.',
    ]
    (args.out / 'table.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines))

    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    if log['evals']:
        t, _, ret = zip(*log['evals'], strict=True)
        ax.plot(np.array(t) / 60, ret, 'o-', label='pixel RL (b): periodic eval, 8 train values')
    student_train = float(student['train']['mean_return'])
    ax.errorbar([wall.mean()], [student_train], xerr=[[wall.mean() - wall.min()],
                [wall.max() - wall.mean()]], fmt='s', color='C2',
                label='distilled student (a), zeus eval train split')
    ax.axhline(float(rl['train']['random_return']), color='grey', ls='--',
               label='uniform random policy')
    ax.set_xlabel('wall time on one core (min)')
    ax.set_ylabel('episode return (train values)')
    ax.set_title('Cheetah-Bias-v0 from pixels: route (a) vs (b)')
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out / 'return_vs_wall.png', dpi=110)


if __name__ == '__main__':
    main()
