"""Pixels too (issue 47, item 5): the pixel student with its retrained teacher's actor.

A continual run retrains the state teacher (its actor only: phi and psi stay). `zeus distill
--refresh` moves the new actor into the zoo's teacher-head pixel student without rendering a
frame (zeus_ros/offline/training/student_refresh.py). This measures, in process on the Bias
drift scenario's values (benchmarks/bench_continual.py's, the same unused seeds as its
references) and on the family's train values, the zoo teacher, each retrained teacher the live
runs left (checkpoints/continual_drift/), the zoo pixel student and the student refreshed from
each, and reports the share of the teacher's gain the student keeps:

    kept = (refreshed student - zoo student) / (retrained teacher - zoo teacher)

    python experiments/pixel_refresh.py            # about 15 min on a busy 2-core CPU

Writes docs/results/continual_drift/pixels/pixel_refresh.csv and .png.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path
import sys
import tempfile
from typing import Any

from drift_scenarios import bench_continual
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
ZOO = REPO / 'checkpoints' / 'cheetah_bias_v0'
TEACHERS = sorted((REPO / 'checkpoints' / 'continual_drift').glob('bias_run*.pt'))
OUT = REPO / 'docs' / 'results' / 'continual_drift' / 'pixels'


def measure(path: Path, contexts: dict[str, list[dict[str, float]]], episodes: int,
            seed: int) -> dict[str, Any]:
    """Mean return per episode (and s.e. over episodes) at each split's values, paired seeds."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts

    agent = InferenceAgent.from_checkpoint(path)
    row: dict[str, Any] = {}
    for split, values in contexts.items():
        returns = np.array([r['return'] for r in evaluate_contexts(
            agent, values, episodes=episodes, seed=seed, progress=True,
            desc=f'{path.stem} {split}')]).reshape(len(values), -1)
        row[f'{split}_return'] = round(float(returns.mean()), 2)
        row[f'{split}_se'] = round(float(returns.mean(0).std(ddof=1) / np.sqrt(episodes)), 2)
        row[f'{split}_per_value'] = ' '.join(f'{v:.1f}' for v in returns.mean(1))
    return row


def main() -> int:
    """Refresh the student from each kept teacher, measure all, write the CSV and PNG."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--episodes', type=int, default=0,
                        help="episodes per value (default: the bench references')")
    parser.add_argument('--out', type=Path, default=OUT)
    args = parser.parse_args()
    import torch

    from zeus_ros.offline.evaluation.evaluate import split_values
    from zeus_ros.offline.training.student_refresh import refresh_student

    torch.set_num_threads(1)
    bench = bench_continual()
    task, _, values = bench.SCENARIOS['bias']
    episodes = args.episodes or bench.REFERENCE_EPISODES
    name = bench._context_name(task)
    contexts = {'scenario': [{name: v} for v in values],
                'train': split_values(task, 'train')}
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as scratch:
        plan = [('teacher', 'zoo', ZOO / 'zeus.pt'), ('student', 'zoo', ZOO / 'pixels_student.pt')]
        for teacher in TEACHERS:
            student = Path(scratch) / f'{teacher.stem}_student.pt'
            refresh_student(ZOO / 'pixels_student.pt', teacher, student, task=task)
            plan += [('teacher', teacher.stem, teacher), ('student', teacher.stem, student)]
        for kind, source, path in plan:
            row = {'kind': kind, 'from': source, **measure(path, contexts, episodes,
                                                           bench.REFERENCE_SEED)}
            rows.append(row)
            print(row, flush=True)
    zoo = {r['kind']: r for r in rows if r['from'] == 'zoo'}
    for row in rows:
        base = zoo[row['kind']]
        row['gain'] = round(row['scenario_return'] - base['scenario_return'], 2)
        row['train_change'] = round(row['train_return'] - base['train_return'], 2)
    for row in rows:
        teacher = next(r for r in rows if r['kind'] == 'teacher' and r['from'] == row['from'])
        row['kept'] = round(row['gain'] / teacher['gain'], 3) if teacher['gain'] > 0 else ''
    args.out.mkdir(parents=True, exist_ok=True)
    with (args.out / 'pixel_refresh.csv').open('w', newline='') as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    _plot(rows, values, args.out / 'pixel_refresh.png')
    for row in rows:
        print(f"{row['kind']:8s} {row['from']:22s} scenario {row['scenario_return']:7.1f} ± "
              f"{row['scenario_se']:.1f}  train {row['train_return']:6.1f}  gain "
              f"{row['gain']:+6.1f}  kept {row['kept']}")
    return 0


def _plot(rows: list[dict[str, Any]], values: list[float], path: Path) -> None:
    """Return per value beyond the range: teacher and student, zoo and each refresh."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for row in rows:
        style = '-' if row['kind'] == 'teacher' else '--'
        ax.plot(values, [float(v) for v in row['scenario_per_value'].split()], style,
                marker='o', label=f"{row['kind']} ({row['from']})")
    ax.set_xlabel('motor bias (beyond the training range)')
    ax.set_ylabel('return per 40-step episode')
    ax.set_title("Cheetah-Bias-v0: the pixel student with its retrained teacher's actor")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == '__main__':
    sys.exit(main())
