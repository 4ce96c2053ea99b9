"""Issue 10: where in an episode a policy loses return, and how exact psi is there.

    python experiments/psi_in_episode.py --runs k10=runs/i10/k10/cheetah_run_v1/zeus_s0 ...
        [--split train] [--episodes 3] [--blocks 8] [--out docs/results/issue10/psi_in_episode]

Each --runs entry is LABEL=RUN_FOLDER or LABEL=CHECKPOINT.pt (a shipped one; repeat a label for
its seeds). Every run drives its own
policy deterministically for --episodes episodes per value of the split at a constant context
(`zeus eval`'s per-value protocol, seed 100). Per label, mean +- s.e. over its runs:
- the reward earned in each of --blocks equal blocks of the episode;
- for runs with a learned psi: psi read as a context value by ONE affine map fitted over every
  step of the run's own episodes (labels only measure here), its RMS error per block, and the
  value it reads on the lowest context value in the last block (a policy that speeds up
  because psi says "faster" shows as a growing error there);
- on full histories, the R^2 of an affine map of psi against the context and against the mean
  reward of the history's own transitions (psi that summarises how well the policy is doing
  rather than the context scores higher on the second).
Writes <out>.csv and <out>.png and prints a table.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
import itertools
from pathlib import Path

import numpy as np
from psi_probe import linear_r2  # same folder: the probe's affine R^2

from zeus_ros.offline.evaluation.evaluate import evaluate_contexts, split_values
from zeus_ros.offline.evaluation.metrics import write_csv
from zeus_ros.offline.evaluation.report import mean_se


def episodes_of(trace, value: float) -> list[dict[str, np.ndarray]]:
    """Episodes of a trace: reward earned by each action, psi where it was taken, the value.

    Observation a starts an episode and b the next one: actions at a..b-2 earned the rewards at
    a+1..b-1 (as Trace.episode_returns counts them).
    """
    starts = [*np.flatnonzero(trace.first).tolist(), len(trace.reward)]
    return [{'reward': trace.reward[a + 1:b],
             'psi': None if trace.psi is None else trace.psi[a:b - 1], 'value': value}
            for a, b in itertools.pairwise(starts) if b - a > 1]


def run_profile(run: Path, split: str, episodes: int, blocks: int) -> dict[str, np.ndarray]:
    """Reward per block and psi's error per block for one run."""
    from zeus_ros.learning.inference import InferenceAgent

    agent = InferenceAgent.from_checkpoint(
        run if run.suffix == '.pt' else run / 'run' / 'final.pt')
    values = split_values(agent.task, split)
    traces: list = []
    evaluate_contexts(agent, values, episodes=episodes, seed=100, progress=False, traces=traces)
    eps = [e for t, v in zip(traces, values, strict=True)
           for e in episodes_of(t, float(next(iter(v.values()))))]
    length = max(len(e['reward']) for e in eps)
    eps = [e for e in eps if len(e['reward']) == length]  # whole episodes only
    edges = np.linspace(0, length, blocks + 1).astype(int)
    reward = np.stack([e['reward'][:length] for e in eps])
    profile = {'reward': np.array([reward[:, a:b].sum(1).mean()
                                   for a, b in itertools.pairwise(edges)])}
    if eps[0]['psi'] is not None and np.asarray(eps[0]['psi']).ndim == 2 \
            and np.asarray(eps[0]['psi']).shape[1] > 0:
        psi = np.stack([e['psi'][:length] for e in eps])  # (E, T, C)
        target = np.array([e['value'] for e in eps])[:, None].repeat(length, 1)
        design = np.c_[psi[:, 1:].reshape(-1, psi.shape[-1]), np.ones(target[:, 1:].size)]
        coef, *_ = np.linalg.lstsq(design, target[:, 1:].ravel(), rcond=None)
        read = (np.c_[psi.reshape(-1, psi.shape[-1]), np.ones(target.size)] @ coef
                ).reshape(target.shape)
        error = read - target
        profile['psi_rms_error'] = np.array([
            np.sqrt((error[:, max(a, 1):b] ** 2).mean())
            for a, b in itertools.pairwise(edges)])
        lowest = target[:, 0] == target[:, 0].min()
        profile['lowest_read_last_block'] = np.array([read[lowest, edges[-2]:].mean()])
        # what psi encodes on full histories: the context, or the mean reward of its history
        k = agent.k
        full = psi[:, k:].reshape(-1, psi.shape[-1])
        history_reward = np.stack([np.convolve(r, np.ones(k) / k, mode='valid')[:length - k]
                                   for r in reward])
        profile['r2_context'] = np.array([linear_r2(full, target[:, k:].ravel())])
        profile['r2_history_reward'] = np.array([linear_r2(full, history_reward.ravel())])
    return profile


def main() -> None:
    """Profile every run, then write the per-label table, CSV and plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--runs', nargs='+', required=True, metavar='LABEL=RUN')
    parser.add_argument('--split', default='train')
    parser.add_argument('--episodes', type=int, default=3)
    parser.add_argument('--blocks', type=int, default=8)
    parser.add_argument('--out', type=Path, default=Path('docs/results/issue10/psi_in_episode'))
    args = parser.parse_args()
    groups: dict[str, list[dict[str, np.ndarray]]] = defaultdict(list)
    for entry in args.runs:
        label, sep, folder = entry.partition('=')
        path = Path(folder)
        if not sep or not ((path.is_file() and path.suffix == '.pt')
                           or (path / 'run' / 'final.pt').is_file()):
            parser.error(f'--runs {entry!r}: expected LABEL=RUN with RUN/run/final.pt, or '
                         'LABEL=CHECKPOINT.pt (a shipped checkpoint)')
        groups[label].append(run_profile(Path(folder), args.split, args.episodes, args.blocks))
        print(f'{label}: {folder} done', flush=True)
    rows = []
    for label, profiles in groups.items():
        for key in profiles[0]:
            stacked = np.stack([p[key] for p in profiles])
            for index in range(stacked.shape[1]):
                mean, se = mean_se(stacked[:, index].tolist())
                rows.append({'label': label, 'seeds': len(profiles), 'quantity': key,
                             'block': index, 'mean': mean, 'se': se})
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_csv(args.out.with_suffix('.csv'), rows)
    for key in ('reward', 'psi_rms_error', 'lowest_read_last_block', 'r2_context',
                'r2_history_reward'):
        for label in groups:
            cells = [f'{r["mean"]:.2f} ± {r["se"]:.2f}' for r in rows
                     if r['label'] == label and r['quantity'] == key]
            if cells:
                print(f'{key:24s} {label:16s} ' + ' | '.join(cells))
    _plot(rows, args.out.with_suffix('.png'), args.split)


def _plot(rows: list[dict], path: Path, split: str) -> None:
    """Reward per block and psi's error per block, one line per label with s.e. bands."""
    from zeus_ros.offline.evaluation.metrics import pyplot

    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for ax, key, title in ((axes[0], 'reward', 'reward per block'),
                           (axes[1], 'psi_rms_error', "psi's error as a context value (RMS)")):
        for label in dict.fromkeys(r['label'] for r in rows):
            sel = [r for r in rows if r['label'] == label and r['quantity'] == key]
            if not sel:
                continue
            x = np.array([r['block'] for r in sel])
            m, s = np.array([r['mean'] for r in sel]), np.array([r['se'] for r in sel])
            ax.plot(x, m, marker='o', label=f'{label} ({sel[0]["seeds"]} seeds)')
            ax.fill_between(x, m - s, m + s, alpha=0.2)
        ax.set_xlabel('block of the episode')
        ax.set_title(f'{title}, {split} values')
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == '__main__':
    main()
