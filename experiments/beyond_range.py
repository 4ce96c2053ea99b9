"""Issue 10: beyond the training range, does inferring the context beat assuming a train one.

    python experiments/beyond_range.py --checkpoints \
        checkpoints/issue10_episodes/default/cheetah_run_v1_50k \
        checkpoints/issue10_episodes/k10/cheetah_run_v1_50k [--split extrapolation] \
        [--episodes 3] [--out docs/results/issue10/beyond_range]

`zeus eval`'s value of adaptation freezes the context at the mean context *of the split being
evaluated*: on the extrapolation values that is the context of an average extrapolation value
(on Cheetah-Run-v1 a target of ~3.6 m/s, between 3.25 and 4.0), so it measures only how well the
policy tells the extrapolation values apart from each other. This asks the question a deployed
robot meets: on a value outside the training range, is acting on the inferred context better than
acting as in the training contexts? Every checkpoint acts on the split's values (`zeus eval`'s
protocol: constant context, evaluation seed 100, --episodes per value) with its context live,
frozen at its mean context over the train values, and frozen at the mean context of the train
value nearest to each value (the best a policy that recognised only training contexts could
pick), and under two deployable guards (FREEZES). Differences are paired on the same
environment seeds; per method, mean ± s.e. over seeds. Writes <out>.csv (summary),
<out>_runs.csv and <out>.png, and prints the table.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path
import re
from typing import Any

import numpy as np

from zeus_ros.offline.evaluation.eval_batch import find_checkpoints
from zeus_ros.offline.evaluation.evaluate import evaluate_contexts, split_values
from zeus_ros.offline.evaluation.metrics import write_csv
from zeus_ros.offline.evaluation.report import mean_se

_NAME = re.compile(r'(?P<method>.+)_s(?P<seed>\d+)$')
FREEZES = ('live', 'train_mean', 'nearest_train', 'train_box', 'snap_outside')
"""How the context is set: live; frozen at the train values' mean; frozen at the nearest train
value's; two deployable guards that need no true context: live clipped into the box the train
values' mean contexts span, and live replaced by the nearest train mean context (Euclidean) when
it leaves that box."""


def _first(value: dict[str, float]) -> float:
    return next(iter(value.values()))


def returns(path: Path, split: str, episodes: int) -> list[dict[str, Any]]:
    """Mean episode return of one checkpoint on `split`, per way of setting its context."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.diagnostics import mean_contexts

    match = _NAME.match(path.stem)
    if match is None:
        raise SystemExit(f'{path}: expected a <method>_s<seed>.pt name (a shipped checkpoint)')
    agent = InferenceAgent.from_checkpoint(path)
    values = split_values(agent.task, split)
    base = {'method': match['method'], 'seed': int(match['seed']), 'split': split}

    def run(frozen: list[np.ndarray] | None, transform: Any = None) -> float:
        rows = evaluate_contexts(agent, values, episodes=episodes, seed=100, progress=False,
                                 frozen=frozen, context_transform=transform)
        return float(np.mean([r['return'] for r in rows]))

    out = [{**base, 'freeze': 'live', 'return': run(None)}]
    if not agent.context_dim:
        return out
    train = split_values(agent.task, 'train')
    traces: list = []
    evaluate_contexts(agent, train, episodes=episodes, seed=100, progress=False, traces=traces)
    means = mean_contexts(agent, traces)
    nearest = [int(np.argmin([abs(_first(t) - _first(v)) for t in train])) for v in values]
    out.append({**base, 'freeze': 'train_mean',
                'return': run([np.mean(means, axis=0) for _ in values])})
    out.append({**base, 'freeze': 'nearest_train', 'return': run([means[i] for i in nearest])})
    low, high, stacked = np.min(means, axis=0), np.max(means, axis=0), np.stack(means)

    def snap(psi: np.ndarray) -> np.ndarray:
        if np.all((psi >= low) & (psi <= high)):
            return psi
        return stacked[int(np.argmin(np.sum((stacked - psi) ** 2, axis=1)))]

    out.append({**base, 'freeze': 'train_box',
                'return': run(None, lambda psi: np.clip(psi, low, high))})
    out.append({**base, 'freeze': 'snap_outside', 'return': run(None, snap)})
    return out


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method: live return, the value of adaptation against each freeze, gain and share."""
    by: dict[tuple[str, str], dict[int, float]] = defaultdict(dict)
    for row in rows:
        by[(row['method'], row['freeze'])][row['seed']] = row['return']
    reference, oracle = by.get(('no_context', 'live'), {}), by.get(('oracle', 'live'), {})
    table = []
    for method in dict.fromkeys(r['method'] for r in rows):
        live = by[(method, 'live')]
        entry: dict[str, Any] = {'method': method, 'seeds': len(live)}
        entry['return'], entry['return_se'] = mean_se(list(live.values()))
        common = sorted(set(live) & set(reference) & set(oracle))
        if method != 'no_context' and len(common) >= 2:
            gain = [live[s] - reference[s] for s in common]
            entry['gain'], entry['gain_se'] = mean_se(gain)
            entry['share'] = float(np.mean(gain) / np.mean([oracle[s] - reference[s]
                                                            for s in common]))
        for freeze in FREEZES[1:]:
            frozen = by.get((method, freeze), {})
            paired = [live[s] - frozen[s] for s in sorted(set(live) & set(frozen))]
            if len(paired) >= 2:
                entry[f'voa_{freeze}'], entry[f'voa_{freeze}_se'] = mean_se(paired)
        table.append(entry)
    return table


def _cell(entry: dict[str, Any], key: str) -> str:
    if key not in entry:
        return '-'
    return f'{entry[key]:.1f} ± {entry[key + "_se"]:.1f}'


def plot(table: list[dict[str, Any]], path: Path, title: str) -> None:
    """Value of adaptation against each freeze, per method (mean ± s.e. over seeds)."""
    from zeus_ros.offline.evaluation.metrics import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4))
    methods = [e for e in table if 'voa_train_mean' in e]
    for offset, freeze in zip((-0.3, -0.1, 0.1, 0.3), FREEZES[1:], strict=True):
        x = np.arange(len(methods)) + offset
        ax.bar(x, [e.get(f'voa_{freeze}', np.nan) for e in methods], width=0.2,
               yerr=[e.get(f'voa_{freeze}_se', np.nan) for e in methods], capsize=3,
               label=f'live minus {freeze.replace("_", " ")}')
    ax.axhline(0, color='grey', lw=0.8)
    ax.set_xticks(np.arange(len(methods)), [e['method'] for e in methods])
    ax.set_ylabel('value of adaptation (return, mean ± s.e.)')
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    """Evaluate every checkpoint live and frozen; write the table and plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--checkpoints', nargs='+', type=Path, required=True,
                        help='shipped checkpoints (<method>_s<seed>.pt) or folders of them')
    parser.add_argument('--split', default='extrapolation')
    parser.add_argument('--episodes', type=int, default=3, help='episodes per context value')
    parser.add_argument('--out', type=Path, default=Path('docs/results/issue10/beyond_range'))
    args = parser.parse_args()
    rows: list[dict[str, Any]] = []
    checkpoints = find_checkpoints(args.checkpoints)
    for index, path in enumerate(checkpoints, 1):
        rows += returns(path, args.split, args.episodes)
        print(f'[{index}/{len(checkpoints)}] {path}', flush=True)
    table = summary(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_csv(args.out.with_suffix('.csv'), table)
    write_csv(Path(f'{args.out}_runs.csv'), rows)
    print(f'{args.split} values | method | seeds | return | gain over no_context (paired) | '
          'share of headroom | live - frozen at train mean | live - frozen at nearest train '
          'value | live - clipped to the train box | live - snapped outside the box |\n'
          '|---|---|---|---|---|---|---|---|---|')
    for e in table:
        share = f'{e["share"]:.2f}' if 'share' in e else '-'
        print(f'| {e["method"]} | {e["seeds"]} | {_cell(e, "return")} | {_cell(e, "gain")} | '
              f'{share} | {_cell(e, "voa_train_mean")} | {_cell(e, "voa_nearest_train")} | '
              f'{_cell(e, "voa_train_box")} | {_cell(e, "voa_snap_outside")} |')
    plot(table, args.out.with_suffix('.png'),
         f'{args.split} values: inferring the context vs assuming a training one')
    print(f'wrote {args.out}.csv, {args.out}_runs.csv and {args.out}.png')


if __name__ == '__main__':
    main()
