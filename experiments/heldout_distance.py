"""Issue 35: how adaptation degrades with the distance from the training range, as a curve.

    OMP_NUM_THREADS=1 nice -n 10 python experiments/heldout_distance.py \
        --task Cheetah-Bias-v0 [--episodes 10] [--threads 1] [--out docs/results/heldout] [--reuse]

Every preset split (params/contexts/<task>.yaml) has chosen something: the train values trained
the policies, the interpolation and extrapolation values picked the defaults. This evaluates the
shipped 50k checkpoints on context values that are in *no* split, at increasing distance from the
training range: between train values, in the gap between the train bands (negative distances:
inside the training hull), just beyond the range and far beyond it (positive distances). Each
value is measured with `zeus eval`'s own evaluator (`evaluate_contexts`: deterministic actions,
constant context, evaluation seed 100 + the value's fixed index, so every method meets the same
initial states), the context live and, for context methods, frozen at the checkpoint's mean
context over the train values (as `experiments/beyond_range.py` freezes it), which says whether
what the policy gains at that distance is adaptation.

Every value is measured anew by default (the committed rows are replaced as the new ones come:
a reader who runs it reproduces the numbers, not re-reads them); `--reuse` keeps the rows
<out>/<task>_50k_runs.csv already holds for this --episodes and measures only the missing ones
(to resume a stopped run, or to redraw the table and figure). Each line says how many values
were measured and how many reused. Rows land in <out>/<task>_50k_runs.csv after every
checkpoint. Then <out>/<task>_50k.csv (per method and distance: return, paired gain
over no_context, share of the oracle's headroom, value of adaptation; mean ± s.e. over seeds,
paired by seed) and <out>/<task>_50k.png.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
import csv
from pathlib import Path
import time
from typing import Any

import numpy as np

from zeus_ros.offline.evaluation.evaluate import evaluate_contexts, split_values
from zeus_ros.offline.evaluation.metrics import write_csv
from zeus_ros.offline.evaluation.report import mean_se

ROOT = Path('checkpoints/issue10_episodes')
CHECKPOINTS: dict[str, dict[str, str]] = {
    # method label -> shipped folder/<file prefix>; `zeus` is each family's default objective
    'Cheetah-Bias-v0': {'no_context': 'default/cheetah_bias_v0_50k/no_context',
                        'oracle': 'default/cheetah_bias_v0_50k/oracle',
                        'zeus': 'default/cheetah_bias_v0_50k/zeus_no_context_loss'},
    'Cheetah-Motor-v0': {'no_context': 'default/cheetah_motor_v0_50k/no_context',
                         'oracle': 'default/cheetah_motor_v0_50k/oracle',
                         'zeus': 'default/cheetah_motor_v0_50k/zeus_no_context_loss'},
    # on the paper's family the default keeps eq. 1 (alpha_psi auto = the paper's value);
    # the ablation without it is shipped at the same budget, so both are measured
    'Cheetah-Run-v1': {'no_context': 'default/cheetah_run_v1_50k/no_context',
                       'oracle': 'default/cheetah_run_v1_50k/oracle',
                       'zeus': 'k10/cheetah_run_v1_50k/zeus',
                       'zeus_no_context_loss': 'k10/cheetah_run_v1_50k/zeus_no_context_loss'},
}


def _sym(*values: float) -> list[float]:
    """Each value on both sides of 0 (the bias families are symmetric)."""
    return [x for a in values for x in (-a, a)]


GRIDS: dict[str, list[tuple[float, list[float]]]] = {
    # (signed distance to the nearest train value: < 0 inside the training hull, > 0 beyond it;
    #  the values at that distance). Append only: a value's evaluation seed is its index.
    'Cheetah-Bias-v0': [(-0.125, _sym(0.025)), (-0.075, _sym(0.075)),
                        (-0.025, _sym(0.175, 0.225, 0.275)), (0.025, _sym(0.325)),
                        (0.05, _sym(0.35)), (0.075, _sym(0.375)), (0.3, _sym(0.6)),
                        (0.35, _sym(0.65)), (0.4, _sym(0.7)), (0.5, _sym(0.8))],
    'Cheetah-Motor-v0': [(-0.1, [0.65, 0.9]), (-0.05, [0.6, 0.95]),
                         (-0.025, [0.425, 0.475, 0.525, 1.025, 1.075, 1.125]),
                         (0.025, [0.375, 1.175]), (0.075, [0.325, 1.225]),
                         (0.125, [0.275, 1.275]), (0.175, [0.225, 1.325]),
                         (0.3, [0.1, 1.45]), (0.6, [1.75]), (0.85, [2.0])],
    'Cheetah-Run-v1': [(-0.215, [0.215, 0.645, 1.075, 1.5, 1.93, 2.355, 2.785]),
                       (0.1, [3.1]), (0.2, [3.2]), (0.375, [3.375]), (0.625, [3.625]),
                       (0.875, [3.875]), (1.25, [4.25]), (1.5, [4.5]), (2.0, [5.0])],
}
RUN_COLUMNS = ('task', 'method', 'seed', 'checkpoint', 'distance', 'value', 'env_seed',
               'episodes', 'freeze', 'return')


def grid(task: str) -> list[tuple[float, float, int]]:
    """(distance, value, evaluation seed) per value, checked to lie in no preset split."""
    parameter = next(iter(split_values(task, 'train')[0]))
    train = [v[parameter] for v in split_values(task, 'train')]
    taken = {round(v[parameter], 6) for s in ('train', 'interpolation', 'extrapolation')
             for v in split_values(task, s)}
    out = []
    for distance, values in GRIDS[task]:
        for value in values:
            if round(value, 6) in taken:
                raise SystemExit(f'{task}: {value} is in a preset split')
            nearest = min(abs(value - t) for t in train)
            inside = min(train) < value < max(train)
            if abs((-nearest if inside else nearest) - distance) > 0.01:
                raise SystemExit(f'{task}: {value} is not at distance {distance}')
            out.append((distance, value, 100 + len(out)))
    return out


def checkpoints(task: str) -> list[tuple[str, int, Path]]:
    """(method, seed, path) of every shipped seed of every method measured on `task`."""
    out = []
    for method, prefix in CHECKPOINTS[task].items():
        folder, stem = (ROOT / prefix).parent, (ROOT / prefix).name
        for path in sorted(folder.glob(f'{stem}_s*.pt')):
            seed = path.stem[len(stem) + 2:]
            if seed.isdigit():
                out.append((method, int(seed), path))
    return out


def measure(task: str, method: str, seed: int, path: Path, points: list[tuple[float, float, int]],
            episodes: int) -> list[dict[str, Any]]:
    """One checkpoint on every grid value: the context live, and frozen at its train mean."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.diagnostics import mean_contexts

    agent = InferenceAgent.from_checkpoint(path)
    parameter = next(iter(split_values(task, 'train')[0]))
    freezes: dict[str, np.ndarray | None] = {'live': None}
    if agent.context_dim:
        traces: list = []  # the train mean as beyond_range.py computes it (3 episodes, seed 100)
        evaluate_contexts(agent, split_values(task, 'train'), episodes=3, seed=100,
                          progress=False, traces=traces)
        freezes['train_mean'] = np.mean(mean_contexts(agent, traces), axis=0)
    rows = []
    for distance, value, env_seed in points:
        for freeze, context in freezes.items():
            result = evaluate_contexts(agent, [{parameter: value}], episodes=episodes,
                                       seed=env_seed, progress=False,
                                       frozen=None if context is None else [context])
            rows.append({'task': task, 'method': method, 'seed': seed, 'checkpoint': str(path),
                         'distance': distance, 'value': value, 'env_seed': env_seed,
                         'episodes': episodes, 'freeze': freeze,
                         'return': float(np.mean([r['return'] for r in result]))})
    return rows


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows a previous (possibly stopped) run wrote, numbers parsed."""
    if not path.exists():
        return []
    with path.open() as f:
        return [{**r, 'seed': int(r['seed']), 'distance': float(r['distance']),
                 'value': float(r['value']), 'env_seed': int(r['env_seed']),
                 'episodes': int(r['episodes']), 'return': float(r['return'])}
                for r in csv.DictReader(f)]


def _ratio(gain: list[float], head: list[float]) -> tuple[float, float]:
    """Share mean(gain) / mean(headroom) and its s.e. (ratio estimator, paired by seed)."""
    g, h = np.asarray(gain), np.asarray(head)
    share = float(g.mean() / h.mean())
    residual = g - share * h
    return share, float(residual.std(ddof=1) / np.sqrt(len(g)) / abs(h.mean()))


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method and distance, mean ± s.e. over seeds; differences paired by seed."""
    per: dict[tuple[str, str, float], dict[int, list[float]]] = defaultdict(
        lambda: defaultdict(list))
    for row in rows:  # a seed's return at a distance: its mean over the values there
        per[(row['method'], row['freeze'], row['distance'])][row['seed']].append(row['return'])
    by = {key: {s: float(np.mean(v)) for s, v in seeds.items()} for key, seeds in per.items()}
    table = []
    for method, freeze, distance in sorted(by, key=lambda k: (k[2], k[0])):
        if freeze != 'live':
            continue
        live = by[(method, 'live', distance)]
        entry: dict[str, Any] = {'distance': distance, 'method': method, 'seeds': len(live)}
        entry['return'], entry['return_se'] = mean_se(list(live.values()))
        ref = by.get(('no_context', 'live', distance), {})
        orc = by.get(('oracle', 'live', distance), {})
        common = sorted(set(live) & set(ref) & set(orc))
        if method != 'no_context' and len(common) >= 2:
            gain = [live[s] - ref[s] for s in common]
            entry['gain'], entry['gain_se'] = mean_se(gain)
            if method != 'oracle':
                entry['share'], entry['share_se'] = _ratio(
                    gain, [orc[s] - ref[s] for s in common])
        frozen = by.get((method, 'train_mean', distance), {})
        paired = [live[s] - frozen[s] for s in sorted(set(live) & set(frozen))]
        if len(paired) >= 2:
            entry['voa_train_mean'], entry['voa_train_mean_se'] = mean_se(paired)
        table.append(entry)
    return table


def plot(table: list[dict[str, Any]], path: Path, title: str) -> None:
    """Return, share of the oracle's headroom and value of adaptation against the distance."""
    from zeus_ros.offline.evaluation.metrics import pyplot

    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    panels = (('return', 'return (mean ± s.e. over seeds)'),
              ('share', "share of the oracle's headroom (paired)"),
              ('voa_train_mean', 'live - frozen at the train mean'))
    methods = list(dict.fromkeys(e['method'] for e in table))
    colours = {m: f'C{i}' for i, m in enumerate(methods)}  # one colour per method, every panel
    for ax, (key, label) in zip(axes, panels, strict=True):
        for method in methods:
            points = [e for e in table if e['method'] == method and key in e]
            if points:
                ax.errorbar([e['distance'] for e in points], [e[key] for e in points],
                            yerr=[e[f'{key}_se'] for e in points], marker='o', capsize=3,
                            label=method, color=colours[method])
        ax.axvline(0, color='grey', lw=0.8, ls='--')
        if key != 'return':
            ax.axhline(1 if key == 'share' else 0, color='grey', lw=0.8)
        ax.set_xlabel('distance to the nearest train value\n(< 0: inside the training hull)')
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _cell(entry: dict[str, Any], key: str, digits: int = 1) -> str:
    if key not in entry:
        return '-'
    return f'{entry[key]:.{digits}f} ± {entry[key + "_se"]:.{digits}f}'


def main(argv: list[str] | None = None) -> None:
    """Measure every value (with --reuse: the missing ones), then write the table and plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--task', choices=sorted(GRIDS), default='Cheetah-Bias-v0')
    parser.add_argument('--episodes', type=int, default=10, help='episodes per context value')
    parser.add_argument('--threads', type=int, default=1, help='torch threads')
    parser.add_argument('--out', type=Path, default=Path('docs/results/heldout'))
    parser.add_argument('--reuse', action='store_true',
                        help='keep the rows OUT/<task>_50k_runs.csv holds for these --episodes '
                        'and measure only the missing values (resume a stopped run; default: '
                        'measure every value anew)')
    args = parser.parse_args(argv)
    import torch

    torch.set_num_threads(args.threads)
    stem = args.out / f'{args.task.lower().replace("-", "_")}_50k'
    runs = Path(f'{stem}_runs.csv')
    rows = read_rows(runs)
    if not args.reuse:  # re-measure: only rows of other --episodes stay (not in this table)
        rows = [r for r in rows if r['episodes'] != args.episodes]
    points = grid(args.task)
    measured = reused = 0
    todo = checkpoints(args.task)
    started = time.monotonic()
    for index, (method, seed, path) in enumerate(todo, 1):
        have = {(r['value'], r['episodes']) for r in rows if r['checkpoint'] == str(path)}
        missing = [p for p in points if (p[1], args.episodes) not in have]
        measured, reused = measured + len(missing), reused + len(points) - len(missing)
        if missing:
            rows += measure(args.task, method, seed, path, missing, args.episodes)
            args.out.mkdir(parents=True, exist_ok=True)
            write_csv(runs, rows, RUN_COLUMNS)
        elapsed = time.monotonic() - started
        print(f'[{index}/{len(todo)}] {path} ({len(missing)} values measured, '
              f'{len(points) - len(missing)} reused, {elapsed:.0f} s so far)', flush=True)
    rows = [r for r in rows if r['episodes'] == args.episodes]
    table = summary(rows)
    write_csv(stem.with_suffix('.csv'), table)
    plot(table, stem.with_suffix('.png'),
         f'{args.task}, 50k updates, values in no preset split ({args.episodes} episodes each)')
    print('| distance | method | seeds | return | gain over no_context | share of headroom | '
          'live - frozen at train mean |\n|---|---|---|---|---|---|---|')
    for e in table:
        print(f'| {e["distance"]:+g} | {e["method"]} | {e["seeds"]} | {_cell(e, "return")} | '
              f'{_cell(e, "gain")} | {_cell(e, "share", 2)} | {_cell(e, "voa_train_mean")} |')
    print(f'{measured} values measured, {reused} reused'
          + (f' (rows kept from {runs}: --reuse)' if reused else ''))
    print(f'wrote {runs}, {stem}.csv and {stem}.png')


if __name__ == '__main__':
    main()
