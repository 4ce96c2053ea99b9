"""Issue 14: what acting on a context L steps old costs (the policy's `context_lag`).

    python experiments/context_lag.py --checkpoints \
        checkpoints/issue10_episodes/default/cheetah_bias_v0_50k [--lags 0 1 2 5] \
        [--split train] [--episodes 3] [--switch-episodes 3] \
        [--out docs/results/issue14/context_lag_bias]

With `context_lag` L the policy node acts on observation k with the estimator's context of step
k - L instead of waiting for context k, which takes the estimator off the step's critical path
(bench_live_loop.py --context-lags 0,1). This measures the price in return, in-process with the
nodes' own code (AgentPolicy), on two protocols: `constant`, zeus eval's per-value episodes
(evaluation seed 100, --episodes per value), where a lag only delays psi's first reading of
each episode; and `switching`, the split's values switching unannounced every quarter episode
(zeus eval's switching run, --switch-episodes episodes), where every switch is read L steps
late. Per (method, protocol, lag): mean ± s.e. over seeds, the paired change against lag 0,
and the paired gain over `no_context` (which has no context, so no lag). Writes <out>.csv,
<out>_runs.csv and <out>.png and prints the table.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path
import re
from typing import Any

import numpy as np
from tqdm import tqdm

from zeus_ros.offline.evaluation.eval_batch import find_checkpoints
from zeus_ros.offline.evaluation.evaluate import (
    default_switch_every,
    evaluate_contexts,
    make_env,
    split_values,
    switch_schedule,
    switching_order,
)
from zeus_ros.offline.evaluation.metrics import read_csv, write_csv
from zeus_ros.offline.evaluation.report import mean_se
from zeus_ros.offline.rollout import run_steps

_NAME = re.compile(r'(?P<method>.+)_s(?P<seed>\d+)$')
SEED = 100
"""zeus eval's evaluation seed: every lag meets the same initial states and schedule."""


def lag_returns(path: Path, lags: list[int], split: str, episodes: int,
                switch_episodes: int) -> list[dict[str, Any]]:
    """Mean episode return of one checkpoint per protocol and lag (lag 0 only without psi)."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.rollout import AgentPolicy

    match = _NAME.match(path.stem)
    if match is None:
        raise SystemExit(f'{path}: expected a <method>_s<seed>.pt name (a shipped checkpoint)')
    agent = InferenceAgent.from_checkpoint(path)
    values = split_values(agent.task, split)
    base = {'task': agent.task, 'method': match['method'], 'seed': int(match['seed']),
            'split': split}
    rows = []
    for lag in lags if agent.context_dim else [0]:
        constant = evaluate_contexts(agent, values, episodes=episodes, seed=SEED,
                                     progress=False, context_lag=lag)
        rows.append({**base, 'protocol': 'constant', 'lag': lag,
                     'return': float(np.mean([r['return'] for r in constant]))})
        schedule = switch_schedule(switching_order(values, SEED),
                                    default_switch_every(agent.task))
        env, task = make_env(agent.task, schedule, SEED)
        try:
            trace = run_steps(env, task, AgentPolicy(agent, noise=0.0, seed=SEED,
                                                     context_lag=lag),
                              switch_episodes * task.episode_length + 1, progress=False)
        finally:
            task.close()
        rows.append({**base, 'protocol': 'switching', 'lag': lag,
                     'return': float(np.mean(trace.episode_returns()[:switch_episodes]))})
    return rows


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (task, method, protocol, lag): return, change against lag 0, gain over no_context."""
    by_seed: dict[tuple[str, str, str, int], dict[int, float]] = defaultdict(dict)
    for row in rows:
        by_seed[(row['task'], row['method'], row['protocol'], row['lag'])][row['seed']] = \
            row['return']
    out = []
    for (task, method, protocol, lag), seeds in sorted(by_seed.items()):
        mean, se = mean_se(list(seeds.values()))
        entry: dict[str, Any] = {'task': task, 'method': method, 'protocol': protocol,
                                 'lag': lag, 'seeds': len(seeds), 'return': mean,
                                 'return_se': se}
        for column, reference in (('change', by_seed.get((task, method, protocol, 0), {})),
                                  ('gain', by_seed.get((task, 'no_context', protocol, 0), {}))):
            if (column == 'change' and lag == 0) or (column == 'gain' and method == 'no_context'):
                reference = {}  # itself: nothing to compare
            common = sorted(set(seeds) & set(reference))
            paired = [seeds[s] - reference[s] for s in common]
            value, value_se = mean_se(paired) if len(common) >= 2 else (None, None)
            entry.update({column: value, f'{column}_se': value_se})
        out.append(entry)
    return out


def plot(table: list[dict[str, Any]], path: Path, title: str) -> None:
    """Return against the lag per method: a row per task, a panel per protocol (mean ± s.e.)."""
    from zeus_ros.offline.evaluation.metrics import pyplot

    plt = pyplot()
    tasks = list(dict.fromkeys(r['task'] for r in table))
    protocols = list(dict.fromkeys(r['protocol'] for r in table))
    fig, axes = plt.subplots(len(tasks), len(protocols), squeeze=False,
                             figsize=(5.5 * len(protocols), 3.6 * len(tasks)))
    for row, task in enumerate(tasks):
        for ax, protocol in zip(axes[row], protocols, strict=True):
            for method in dict.fromkeys(r['method'] for r in table):
                sel = [r for r in table if (r['task'], r['method'], r['protocol'])
                       == (task, method, protocol)]
                if not sel:
                    continue
                label = f'{method} ({sel[0]["seeds"]} seeds)'
                if len(sel) == 1:  # no context, so no lag: a reference line
                    ax.axhline(sel[0]['return'], ls='--', color='grey', label=label)
                    continue
                ax.errorbar([r['lag'] for r in sel], [r['return'] for r in sel],
                            yerr=[r['return_se'] for r in sel], marker='o', capsize=3,
                            label=label)
            ax.set_xlabel('context_lag (steps)')
            ax.set_ylabel('episode return (mean ± s.e.)')
            ax.set_title(f'{task}, {protocol}', fontsize=10)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _pm(value: float | None, se: float | None) -> str:
    return '-' if value is None else f'{value:.1f} ± {se:.1f}'


def main() -> None:
    """Evaluate every checkpoint at every lag; write the tables and the plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--checkpoints', nargs='+', type=Path, default=[],
                        help='shipped checkpoints (<method>_s<seed>.pt) or folders of them')
    parser.add_argument('--lags', nargs='+', type=int, default=[0, 1, 2, 5])
    parser.add_argument('--split', default='train')
    parser.add_argument('--episodes', type=int, default=3, help='episodes per context value')
    parser.add_argument('--switch-episodes', type=int, default=3,
                        help='episodes of the switching run')
    parser.add_argument('--out', type=Path, default=Path('docs/results/issue14/context_lag'))
    parser.add_argument('--rows', type=Path,
                        help="an earlier run's <out>_runs.csv: tabulate and plot it again, "
                        'evaluating nothing')
    args = parser.parse_args()
    if any(lag < 0 for lag in args.lags):
        parser.error(f'--lags: steps must be >= 0, got {args.lags}')
    if args.episodes < 1 or args.switch_episodes < 1:
        parser.error('--episodes and --switch-episodes must be >= 1')
    if not args.checkpoints and not args.rows:
        parser.error('give --checkpoints (or --rows of an earlier run)')
    lags = sorted(set(args.lags) | {0})
    rows = read_csv(args.rows) if args.rows else []
    for path in [] if args.rows else tqdm(find_checkpoints(args.checkpoints),
                                          desc='checkpoints', unit='ckpt'):
        rows += lag_returns(path, lags, args.split, args.episodes, args.switch_episodes)
    table = summary(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_csv(args.out.with_suffix('.csv'), table)
    write_csv(Path(f'{args.out}_runs.csv'), rows)
    print(f'{args.split} values; change = paired against the same method at lag 0; gain = '
          'paired over no_context\n\n| task | method | protocol | lag | seeds | return | change |'
          ' gain over no_context |\n|---|---|---|---|---|---|---|---|')
    for r in table:
        print(f'| {r["task"]} | {r["method"]} | {r["protocol"]} | {r["lag"]} | {r["seeds"]} | '
              f'{r["return"]:.1f} ± {r["return_se"]:.1f} | {_pm(r["change"], r["change_se"])} |'
              f' {_pm(r["gain"], r["gain_se"])} |')
    tasks = ', '.join(dict.fromkeys(r['task'] for r in table))
    plot(table, args.out.with_suffix('.png'),
         f'{tasks}, {args.split} values: the cost of acting on a context L steps old')
    print(f'wrote {args.out}.csv, {args.out}_runs.csv and {args.out}.png')


if __name__ == '__main__':
    main()
