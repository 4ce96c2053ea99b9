r"""docs/results/pixels/: the distilled pixel students against their state teacher.

    python scripts/pixels_student_results.py --teacher checkpoints/cheetah_bias_v0/zeus.pt \\
        --students runs/pixels_student/student_s*/student.pt \\
        --no-context runs/pixels_student/no_context_s*/student.pt

Each checkpoint is measured as `zeus adaptation --checkpoint <student> --against <teacher>`
measures it (adaptation.measure_adaptation, evaluation seed 200, --episodes per value),
cached as JSON in runs/pixels_student/measured/; then one table (mean ± s.e. over seeds of each
seed's mean over values) and one figure (returns per split; the DAgger rounds' losses from
rounds.csv). Pixel agents get their context sensitivity from a rerun that keeps the frames.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[1] / 'docs' / 'results' / 'pixels'
SPLITS = ('train', 'extrapolation')
CACHE = Path(__file__).resolve().parents[1] / 'runs' / 'pixels_student' / 'measured'


def _pixel_sensitivity(path: Path, episodes: int) -> float:
    """context_sensitivity for a pixel agent, on the frame stacks it acted on.

    The evaluation traces keep states only, so the two extreme train values are run again
    here, keeping each step's stack: mean |delta action| (in [-1, 1] units) when the mean psi
    of the other extreme replaces the live psi, over the steps with a full history.
    """
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.adaptation import EVAL_SEED
    from zeus_ros.offline.evaluation.diagnostics import extreme_indices
    from zeus_ros.offline.evaluation.evaluate import make_env, split_values
    from zeus_ros.offline.rollout import AgentPolicy, run_steps

    class Recording(AgentPolicy):
        def _observation(self, es: object, rec: object) -> np.ndarray:
            obs = super()._observation(es, rec)
            self.seen.append(obs)
            return obs

    agent = InferenceAgent.from_checkpoint(path)
    values = split_values(agent.task, 'train')
    runs = []
    for index in extreme_indices(values):
        env, task = make_env(agent.task, {'kind': 'constant', 'context': values[index]},
                              EVAL_SEED + index)
        policy = Recording(agent, noise=0.0, seed=EVAL_SEED)
        policy.seen = []
        try:
            trace = run_steps(env, task, policy, episodes * task.episode_length + 1,
                              progress=False)
        finally:
            task.close()
        full = trace.history_length >= agent.k
        runs.append((np.stack(policy.seen)[full], trace.psi[full]))
    half_range = (agent.action_high - agent.action_low) / 2
    deltas = []
    for (obs, live), (_, other) in ((runs[0], runs[1]), (runs[1], runs[0])):
        replaced = np.repeat(other.mean(0, keepdims=True), len(obs), axis=0)
        delta = agent.agent.act(obs, live) - agent.agent.act(obs, replaced)
        deltas.append(float(np.mean(np.abs(delta) / half_range)))
    return float(np.mean(deltas))


def _measure(path: Path, episodes: int) -> dict:
    """measure_adaptation's numbers for `path`, cached (+ a pixel agent's sensitivity).

    The cache key is the file's sha256: students of two families never share an entry.
    """
    digest = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
    cache = CACHE / f'{path.parent.name}_{path.stem}_{digest}_e{episodes}.json'
    if cache.is_file():
        return json.loads(cache.read_text())
    from zeus_ros.offline.evaluation.adaptation import measure_adaptation

    report = measure_adaptation(path, episodes=episodes, progress=False)
    data = {'method': report.method, 'returns': report.returns,
            'adaptation': report.adaptation, 'sensitivity': report.sensitivity}
    if report.adaptation and data['sensitivity'] != data['sensitivity']:  # NaN: pixels
        data['sensitivity'] = _pixel_sensitivity(path, episodes)
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps(data))
    return data


def _random_returns(task: str, episodes: int) -> dict[str, float]:
    """The uniform random policy's mean return per split (same values, episodes and seed)."""
    from zeus_ros.offline.evaluation.adaptation import EVAL_SEED, _per_value
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts, split_values

    return {split: float(_per_value(evaluate_contexts(
        None, split_values(task, split), episodes=episodes, seed=EVAL_SEED, task_name=task,
        progress=False), episodes).mean()) for split in SPLITS}


def _over_seeds(values: list[float]) -> str:
    array = np.asarray(values, float)
    if len(array) == 1:
        return f'{array[0]:.1f} (1 seed)'
    return f'{array.mean():.1f} ± {array.std(ddof=1) / np.sqrt(len(array)):.1f}'


def _row(label: str, reports: list[dict], teacher: dict, random: dict[str, float]) -> str:
    """Returns, the share of the teacher's gain over random, adaptation, sensitivity."""
    cells = [label, str(len(reports))]
    for split in SPLITS:
        returns = [r['returns'][split][0] for r in reports]
        cells.append(_over_seeds(returns))
        gain = teacher['returns'][split][0] - random[split]
        cells.append(f'{(np.mean(returns) - random[split]) / gain:.2f}')
    for split in SPLITS:
        gains = [r['adaptation'][split] for r in reports if split in r['adaptation']]
        cells.append('-' if not gains else ' / '.join(f'{m:+.1f} ± {se:.1f}' for m, se in gains))
    sens = [r['sensitivity'] for r in reports if r['sensitivity'] == r['sensitivity']]
    cells.append('-' if not sens else f'{np.mean(sens):.3f}')
    return '| ' + ' | '.join(cells) + ' |'


def _figure(groups: dict[str, list[dict]], rounds: dict[str, list[Path]], path: Path) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6))
    width = 0.8 / len(groups)
    for i, (label, reports) in enumerate(groups.items()):
        for j, split in enumerate(SPLITS):
            values = [r['returns'][split][0] for r in reports]
            left.bar(j + i * width, np.mean(values), width, label=label if j == 0 else None,
                     color=f'C{i}')
            left.scatter([j + i * width] * len(values), values, color='k', s=8, zorder=3)
    left.set_xticks([k + 0.4 - width / 2 for k in range(len(SPLITS))], ['train', 'beyond range'])
    left.set_ylabel('return (mean over values; dots: seeds)')
    left.legend(fontsize=7)
    for i, (label, files) in enumerate(rounds.items()):
        for n, file in enumerate(files):
            with file.open() as handle:
                rows = list(csv.DictReader(handle))
            x = [int(r['updates']) for r in rows]
            right.plot(x, [float(r['loss/action']) for r in rows], color=f'C{i + 1}',
                       marker='o', label=f'{label}: action MSE' if n == 0 else None)
            if 'loss/psi' in rows[0]:
                right.plot(x, [float(r['loss/psi']) for r in rows], color=f'C{i + 1}', ls='--',
                           marker='x', label=f'{label}: psi MSE / var' if n == 0 else None)
    right.set_xlabel('regression updates (end of each DAgger round)')
    right.set_ylabel('mean loss of the round')
    right.set_yscale('log')
    right.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    """Measure, tabulate, plot."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--teacher', type=Path, required=True)
    parser.add_argument('--teacher-task', default='Cheetah-Bias-v0')
    parser.add_argument('--episodes', type=int, default=1, help='episodes per context value')
    parser.add_argument('--students', type=Path, nargs='+', required=True)
    parser.add_argument('--no-context', type=Path, nargs='*', default=[])
    parser.add_argument('--teacher-head', type=Path, nargs='*', default=[],
                        help="students of `zeus distill --head teacher` (the teacher's psi and "
                        'actor, frozen, on a pixel phi)')
    parser.add_argument('--out', type=Path, default=OUT,
                        help=f'folder for table.md and the figure (default {OUT})')
    args = parser.parse_args()
    out = args.out
    teacher = _measure(args.teacher, args.episodes)
    random = _random_returns(args.teacher_task, args.episodes)
    groups = {'state teacher': [teacher],
              'pixel student': [_measure(p, args.episodes) for p in args.students]}
    if args.no_context:
        groups['pixel no_context student'] = [_measure(p, args.episodes)
                                              for p in args.no_context]
    if args.teacher_head:
        groups['pixel student, teacher head'] = [_measure(p, args.episodes)
                                                 for p in args.teacher_head]
    out.mkdir(parents=True, exist_ok=True)
    header = ('| checkpoint | seeds | return train | share of teacher | return beyond range '
              '| share of teacher | adaptation train (per seed) '
              '| adaptation beyond range (per seed) | sensitivity |')
    lines = [header, '|' + '---|' * 9]
    lines += [_row(label, reports, teacher, random) for label, reports in groups.items()]
    lines.append(f'| uniform random policy | - | {random["train"]:.1f} | 0 | '
                 f'{random["extrapolation"]:.1f} | 0 | - | - | - |')
    (out / 'table.md').write_text('\n'.join(lines) + '\n')
    rounds = {'student': [p.parent / 'rounds.csv' for p in args.students]}
    if args.no_context:
        rounds['no_context student'] = [p.parent / 'rounds.csv' for p in args.no_context]
    if args.teacher_head:
        rounds['teacher head'] = [p.parent / 'rounds.csv' for p in args.teacher_head]
    _figure(groups, rounds, out / 'returns_and_losses.png')
    print('\n'.join(lines))


if __name__ == '__main__':
    main()
