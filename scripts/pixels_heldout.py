r"""Pixel students on context values in no split: the check of a choice made on the splits.

    python scripts/pixels_heldout.py --teacher checkpoints/cheetah_bias_v0/zeus.pt \\
        --group 'teacher head, 9,600 updates=runs/pixels_teacher_head/bias/r6_s*/student.pt' \\
        --group 'own head=runs/pixels_student/student_s*/student.pt' \\
        --out docs/results/pixels/heldout/cheetah_bias_v0

Why: the beyond-range split (8 values) has been looked at while choosing between students (the
head, the number of updates), so a number on it is no longer a clean test. This measures the
same checkpoints, the state teacher and the uniform random policy on values of no split
(default: Cheetah-Bias-v0's biases +-0.375 ... +-0.525, between and beside the beyond-range
split's values), with other initial states (seed 300; the splits use 200), live psi,
deterministic, `--episodes` per value. Table: per group, mean ± s.e. over seeds of each seed's
mean over values, and the share of the teacher's gain over random; one CSV row per checkpoint
and value. Each checkpoint's returns are cached in runs/pixels_heldout/ by its sha256.
"""

from __future__ import annotations

import argparse
import csv
import glob
import hashlib
import json
from pathlib import Path

import numpy as np

HELDOUT_BIAS = (-0.525, -0.475, -0.425, -0.375, 0.375, 0.425, 0.475, 0.525)
SEED = 300
CACHE = Path(__file__).resolve().parents[1] / 'runs' / 'pixels_heldout'


def _returns(checkpoint: Path | None, task: str, values: list[dict[str, float]],
             episodes: int) -> np.ndarray:
    """Mean return per value (None: the uniform random policy), cached by file hash in CACHE."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts

    what = 'random' if checkpoint is None else hashlib.sha256(checkpoint.read_bytes()).hexdigest()
    key = hashlib.sha256(json.dumps([what, task, values, episodes, SEED]).encode()).hexdigest()
    cache = CACHE / f'{key[:20]}.json'
    if cache.is_file():
        return np.array(json.loads(cache.read_text()), float)
    agent = None if checkpoint is None else InferenceAgent.from_checkpoint(
        checkpoint, reuse_features=True)
    rows = evaluate_contexts(agent, values, episodes=episodes, seed=SEED, task_name=task,
                             progress=False)
    returns = np.array([row['return'] for row in rows], float).reshape(-1, episodes).mean(1)
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps(returns.tolist()))
    return returns


def main() -> None:
    """Measure every group, the teacher and random; write table.md and returns.csv."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--teacher', type=Path, required=True)
    parser.add_argument('--group', action='append', required=True,
                        help="'LABEL=GLOB[,GLOB...]': the seeds of one kind of student")
    parser.add_argument('--parameter', default='motor_bias')
    parser.add_argument('--values', type=float, nargs='+', default=list(HELDOUT_BIAS))
    parser.add_argument('--episodes', type=int, default=1)
    parser.add_argument('--out', type=Path, required=True)
    args = parser.parse_args()
    from zeus_ros.learning.inference import InferenceAgent

    task = InferenceAgent.from_checkpoint(args.teacher).task
    values = [{args.parameter: value} for value in args.values]
    groups: dict[str, list[Path]] = {}
    for item in args.group:
        label, _, patterns = item.partition('=')
        paths = sorted(Path(p) for pattern in patterns.split(',') for p in glob.glob(pattern))
        if not paths:
            raise SystemExit(f'--group {item!r}: no checkpoint matches')
        groups[label] = paths
    random = _returns(None, task, values, args.episodes)
    teacher = _returns(args.teacher, task, values, args.episodes)
    gain = teacher.mean() - random.mean()
    measured = {label: [(path, _returns(path, task, values, args.episodes)) for path in paths]
                for label, paths in groups.items()}
    args.out.mkdir(parents=True, exist_ok=True)
    with (args.out / 'returns.csv').open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(['group', 'checkpoint', args.parameter, 'return'])
        for label, runs in [('state teacher', [(args.teacher, teacher)]),
                            ('uniform random', [(Path('-'), random)]),
                            *measured.items()]:
            for path, returns in runs:
                writer.writerows([label, str(path), value[args.parameter], f'{ret:.2f}']
                                 for value, ret in zip(values, returns, strict=True))
    lines = [f'{task}, {args.parameter} in {args.values} (in no split), seed {SEED}, '
             f'{args.episodes} episode(s) per value, live psi', '',
             '| checkpoint | seeds | return (mean ± s.e. over seeds) | per seed | share of the '
             "teacher's gain over random |", '|---|---|---|---|---|',
             f'| state teacher | 1 | {teacher.mean():.1f} | - | 1 |']
    for label, runs in measured.items():
        means = np.array([returns.mean() for _, returns in runs])
        spread = (f'± {means.std(ddof=1) / np.sqrt(len(means)):.1f}' if len(means) > 1
                  else '(1 seed)')
        share = (means.mean() - random.mean()) / gain
        lines.append(f'| {label} | {len(means)} | {means.mean():.1f} {spread} | '
                     + ', '.join(f'{m:.1f}' for m in means) + f' | {share:.2f} |')
    lines.append(f'| uniform random policy | - | {random.mean():.1f} | - | 0 |')
    (args.out / 'table.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines))


if __name__ == '__main__':
    main()
