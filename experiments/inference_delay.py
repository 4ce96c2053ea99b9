"""Issue 10: how much of the oracle's lead is left to an estimator that must see first.

    python experiments/inference_delay.py --checkpoints \
        checkpoints/issue10_episodes/default/cheetah_run_v1_10k \
        checkpoints/issue10_episodes/k10/cheetah_run_v1_10k [--blind 0 5 10 20 40] \
        [--split train] [--episodes 3] [--out docs/results/issue10/inference_delay]

Every checkpoint acts on the split's values with `zeus eval`'s per-value protocol (constant
context, evaluation seed 100, --episodes per value), its context frozen at its own mean context
(the value-of-adaptation diagnostic's) for the first d steps of every episode and live after
that. For the oracle, d steps blind is an oracle that, like any estimator, needs d steps before
it knows the target: its return at d = k bounds what inferring the context from k transitions
can recover (a policy trained to act blind might hedge better in those steps; this one acts on
the mean context). Per (method, d): mean ± s.e. over seeds, and for methods with a context the
share of the oracle's headroom over `no_context` (paired by seed, the oracle at d = 0 as 1).
Writes <out>.csv and <out>.png and prints the table.
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


def delay_returns(path: Path, blind: list[int], split: str, episodes: int) -> list[dict[str, Any]]:
    """Mean episode return of one checkpoint per number of blind steps."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.diagnostics import frozen_contexts

    match = _NAME.match(path.stem)
    if match is None:
        raise SystemExit(f'{path}: expected a <method>_s<seed>.pt name (a shipped checkpoint)')
    agent = InferenceAgent.from_checkpoint(path)
    values = split_values(agent.task, split)
    traces: list = []
    live = evaluate_contexts(agent, values, episodes=episodes, seed=100, progress=False,
                             traces=traces)
    base = {'method': match['method'], 'seed': int(match['seed']), 'split': split}
    rows = [{**base, 'blind_steps': 0, 'return': float(np.mean([r['return'] for r in live]))}]
    frozen = frozen_contexts(agent, traces, values) if agent.context_dim else None
    for steps in (d for d in blind if d > 0 and frozen is not None):
        blinded = evaluate_contexts(agent, values, episodes=episodes, seed=100, progress=False,
                                    frozen=frozen['mean'], blind_steps=steps)
        rows.append({**base, 'blind_steps': steps,
                     'return': float(np.mean([r['return'] for r in blinded]))})
    return rows


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (method, blind steps): mean ± s.e. and the share of the oracle's headroom kept."""
    by_seed: dict[tuple[str, int], dict[int, float]] = defaultdict(dict)
    for row in rows:
        by_seed[(row['method'], row['blind_steps'])][row['seed']] = row['return']
    reference = by_seed.get(('no_context', 0), {})
    oracle = by_seed.get(('oracle', 0), {})
    out = []
    for (method, steps), seeds in sorted(by_seed.items()):
        mean, se = mean_se(list(seeds.values()))
        common = sorted(set(seeds) & set(reference) & set(oracle))
        gain = [seeds[s] - reference[s] for s in common]
        headroom = [oracle[s] - reference[s] for s in common]
        share = (float(np.mean(gain) / np.mean(headroom))
                 if len(common) >= 2 and method != 'no_context' and np.mean(headroom) else None)
        gain_mean, gain_se = mean_se(gain) if len(common) >= 2 else (None, None)
        out.append({'method': method, 'blind_steps': steps, 'seeds': len(seeds),
                    'return': mean, 'return_se': se, 'gain': gain_mean, 'gain_se': gain_se,
                    'share': share})
    return out


def plot(table: list[dict[str, Any]], path: Path, title: str) -> None:
    """Return against blind steps per method (mean ± s.e.), no_context as a line."""
    from zeus_ros.offline.evaluation.metrics import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for method in dict.fromkeys(r['method'] for r in table):
        sel = [r for r in table if r['method'] == method]
        x = np.array([r['blind_steps'] for r in sel])
        m, s = np.array([r['return'] for r in sel]), np.array([r['return_se'] for r in sel])
        if len(sel) == 1:
            ax.axhline(m[0], ls='--', color='grey', label=f'{method} ({sel[0]["seeds"]} seeds)')
            continue
        ax.errorbar(x, m, yerr=s, marker='o', capsize=3,
                    label=f'{method} ({sel[0]["seeds"]} seeds)')
    ax.set_xlabel('steps blind at the start of each episode (context frozen at its mean)')
    ax.set_ylabel('episode return (mean ± s.e. over seeds)')
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    """Evaluate every checkpoint at every number of blind steps; write the table and plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--checkpoints', nargs='+', type=Path, required=True,
                        help='shipped checkpoints (<method>_s<seed>.pt) or folders of them')
    parser.add_argument('--blind', nargs='+', type=int, default=[0, 5, 10, 20, 40])
    parser.add_argument('--split', default='train')
    parser.add_argument('--episodes', type=int, default=3, help='episodes per context value')
    parser.add_argument('--out', type=Path, default=Path('docs/results/issue10/inference_delay'))
    args = parser.parse_args()
    if any(d < 0 for d in args.blind):
        parser.error(f'--blind: steps must be >= 0, got {args.blind}')
    rows = []
    checkpoints = find_checkpoints(args.checkpoints)
    for index, path in enumerate(checkpoints, 1):
        rows += delay_returns(path, sorted(set(args.blind) | {0}), args.split, args.episodes)
        print(f'[{index}/{len(checkpoints)}] {path}', flush=True)
    table = summary(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_csv(args.out.with_suffix('.csv'), table)
    write_csv(Path(f'{args.out}_runs.csv'), rows)
    print('| method | steps blind | seeds | return | gain over no_context (paired) | share of '
          "the oracle's headroom |\n|---|---|---|---|---|---|")
    for r in table:
        gain = '-' if r['gain'] is None else f'{r["gain"]:.1f} ± {r["gain_se"]:.1f}'
        share = '-' if r['share'] is None else f'{r["share"]:.2f}'
        print(f'| {r["method"]} | {r["blind_steps"]} | {r["seeds"]} | {r["return"]:.1f} ± '
              f'{r["return_se"]:.1f} | {gain} | {share} |')
    plot(table, args.out.with_suffix('.png'), f'{args.split} values: the cost of knowing later')
    print(f'wrote {args.out}.csv, {args.out}_runs.csv and {args.out}.png')


if __name__ == '__main__':
    main()
