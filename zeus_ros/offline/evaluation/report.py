"""`zeus report`: mean and standard error over seeds of `zeus eval` summaries per method, split.

    zeus report runs/exp/walker_walk_v0 --out docs/results/walker_walk_v0

Reads every finished evaluation below the folder: any folder with the eval.json that `zeus eval`
writes last (method, seed and split from it: `zeus eval --checkpoint runs/x/final.pt` writes
runs/x/eval_<split>/, so `zeus report runs/x` finds it), and the layout of
`experiments/run_one.sh` and sweeps, <method>_s<seed>/eval_<split>/summary.csv, finished
where <method>_s<seed>/state.json (or an old .done marker) says so (offline/runs.py).
Writes summary.csv, returns.png, table.md, runs.csv (every seed's numbers) and wall_times.md
into --out (default FOLDER/report) and prints the markdown table (as in docs/results.md).
"""

from __future__ import annotations

from collections import defaultdict
import csv
from dataclasses import dataclass
from pathlib import Path
import re
from typing import Any

import numpy as np

from sim_bridge.presets import SPLITS
from zeus_ros.labels import task_label
from zeus_ros.learning.methods import METHODS
from zeus_ros.offline.evaluation.diagnostics import DIAGNOSTICS
from zeus_ros.offline.evaluation.records import find_records
from zeus_ros.offline.runs import RunState, read_state

__all__ = [
    'METRICS',
    'RUN_NAME',
    'ReportError',
    'diagnostics_table',
    'headroom_rows',
    'headroom_table',
    'markdown_table',
    'mean_se',
    'method_order_key',
    'paired_difference',
    'per_method',
    'per_run',
    'wall_time_table',
    'write_report',
]


class ReportError(ValueError):
    """Nothing to report, or evaluations that do not belong in one table: the message says."""


METRICS = ('mean_return', 'switching_return', 'mean_latency', 'spearman', *DIAGNOSTICS)
"""Columns of an eval summary that are averaged over seeds."""
REFERENCE, BOUND = 'no_context', 'oracle'
"""Headroom = BOUND - REFERENCE: what knowing the context is worth on a split."""
RUN_NAME = re.compile(r'^(?P<method>.+)_s(?P<seed>\d+)$')
SPLIT_ORDER = SPLITS
METHOD_ORDER = METHODS


def mean_se(values: list[float]) -> tuple[float, float]:
    """Mean and standard error of the mean (0 for a single value)."""
    array = np.asarray(values, dtype=np.float64)
    se = float(array.std(ddof=1) / np.sqrt(len(array))) if len(array) > 1 else 0.0
    return float(array.mean()), se


def _rank(name: str, order: tuple[str, ...]) -> tuple[int, str]:
    return (order.index(name) if name in order else len(order), name)


def method_order_key(method: str) -> tuple[int, str]:
    """Sort key that lists methods as every table does: zeus first, oracle last."""
    return _rank(method, METHOD_ORDER)


def _seconds(value: float | None) -> str:
    """Wall seconds from a run's state ('' if not recorded)."""
    return '' if value is None else f'{value:.1f}'.removesuffix('.0')


@dataclass(frozen=True)
class Finished:
    """One finished evaluation of one run on one split, and the run's times."""

    method: str
    seed: int
    split: str
    summary: Path
    state: RunState
    eval_seconds: float | None


def _finished_summaries(folder: Path) -> list[Finished]:
    """Every finished evaluation below `folder`, one per (method, seed, split): the newest.

    Two layouts: <method>_s<seed>/eval_<split>/ that <method>_s<seed>/state.json (or an old
    .done marker) says finished (sweeps, run_one.sh, `zeus eval` on many), and any folder
    with an eval.json, which `zeus eval` writes last (`zeus eval --checkpoint runs/x/final.pt`
    without --out: runs/x/eval_<split>/). A folder holding several tasks is refused.
    """
    found: dict[tuple[str, int, str], tuple[int, Finished]] = {}

    def keep(item: Finished) -> None:
        key, when = (item.method, item.seed, item.split), item.summary.stat().st_mtime_ns
        if key not in found or when > found[key][0]:
            found[key] = (when, item)

    states: dict[Path, RunState] = {}
    legacy = set()
    for summary in sorted(folder.glob('*/eval_*/summary.csv')):
        run, split = summary.parent.parent, summary.parent.name.removeprefix('eval_')
        match = RUN_NAME.match(run.name)
        if match is None:
            continue
        state = states.setdefault(run, read_state(run))
        if split in state.evaluated:
            legacy.add(summary.parent.resolve())
            keep(Finished(match['method'], int(match['seed']), split, summary, state,
                          state.evaluated[split]))
    records = [r for r in find_records(folder) if r.folder.resolve() not in legacy]
    tasks = sorted({r.task for r in records})
    if len(tasks) > 1:
        raise ReportError(f'{folder}: evaluations of {len(tasks)} tasks ({", ".join(tasks)}); '
                          'report the folder of one task')
    for record in records:
        run = Path(record.checkpoint).parent  # the training run's state.json, if it has one
        state = states.setdefault(run, read_state(run))
        keep(Finished(record.method, record.seed, record.split, record.summary, state,
                      record.seconds))
    return [item for _when, item in found.values()]


def per_run(folder: Path) -> list[dict[str, Any]]:
    """One row per finished (run, split): method, seed, split and the agent's metrics."""
    rows = []
    for done in _finished_summaries(folder):
        with done.summary.open(newline='') as handle:
            for row in csv.DictReader(handle):
                if row['policy'] == 'agent':
                    rows.append({'method': done.method, 'seed': done.seed,
                                 'split': row['split'],
                                 **{metric: row.get(metric, '') for metric in METRICS},
                                 'train_seconds': _seconds(done.state.train_seconds),
                                 # a longer run resumed from a shorter one: that one's seconds
                                 'earlier_train_seconds': _seconds(
                                     done.state.earlier_train_seconds),
                                 'eval_seconds': _seconds(done.eval_seconds)})
    return sorted(rows, key=lambda r: (method_order_key(r['method']), r['seed'],
                                       _rank(r['split'], SPLIT_ORDER)))


def per_method(folder: Path) -> list[dict[str, Any]]:
    """One row per (method, split): seeds, then mean and s.e. of every metric with data."""
    table: dict[tuple[str, str], dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    random_returns: dict[str, list[float]] = defaultdict(list)
    for done in _finished_summaries(folder):
        with done.summary.open(newline='') as handle:
            for row in csv.DictReader(handle):
                if row['policy'] == 'random':
                    random_returns[row['split']].append(float(row['mean_return']))
                    continue
                key = (done.method, row['split'])
                for metric in METRICS:
                    value = row.get(metric)
                    if value and value.lower() not in ('nan', 'inf'):
                        table[key][metric].append(float(value))
                table[key]['seeds'].append(float(done.seed))
    rows = []
    for method, split in sorted(table, key=lambda k: (method_order_key(k[0]),
                                                      _rank(k[1], SPLIT_ORDER))):
        metrics = table[(method, split)]
        row: dict[str, Any] = {'method': method, 'split': split, 'seeds': len(metrics['seeds'])}
        for metric in METRICS:
            if metrics.get(metric):
                row[metric], row[f'{metric}_se'] = mean_se(metrics[metric])
        if random_returns.get(split):
            row['random_return'] = float(np.mean(random_returns[split]))
        rows.append(row)
    return rows


def paired_difference(runs: list[dict[str, Any]], method: str, other: str, split: str,
                      metric: str = 'mean_return') -> tuple[float, float, int] | None:
    """Mean and s.e. over seeds of method - other, paired by seed; None below two seeds.

    Runs of one seed share collection and evaluation seeds, so pairing removes their noise.
    """
    def by_seed(name: str) -> dict[int, float]:
        return {r['seed']: float(r[metric]) for r in runs if r['method'] == name
                and r['split'] == split and r.get(metric) not in ('', None)}

    mine, theirs = by_seed(method), by_seed(other)
    common = sorted(set(mine) & set(theirs))
    if len(common) < 2:
        return None
    mean, se = mean_se([mine[s] - theirs[s] for s in common])
    return mean, se, len(common)


def headroom_rows(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per split and method: gain over no_context (paired), headroom and share recovered.

    Share recovered = (method - no_context) / (oracle - no_context), on the paired means.
    """
    rows = []
    splits = sorted({r['split'] for r in runs}, key=lambda s: _rank(s, SPLIT_ORDER))
    methods = sorted({r['method'] for r in runs}, key=method_order_key)
    for split in splits:
        headroom = paired_difference(runs, BOUND, REFERENCE, split)
        for method in methods:
            if method == REFERENCE:
                continue
            gain = paired_difference(runs, method, REFERENCE, split)
            if gain is None:
                continue
            row = {'split': split, 'method': method, 'seeds': gain[2], 'gain': gain[0],
                   'gain_se': gain[1]}
            if headroom is not None:
                row['headroom'], row['headroom_se'] = headroom[0], headroom[1]
                if abs(headroom[0]) > 0:
                    row['recovered'] = gain[0] / headroom[0]
            rows.append(row)
    return rows


def headroom_table(rows: list[dict[str, Any]]) -> str:
    """Markdown of headroom_rows: gains in return units, mean ± s.e. of paired differences."""
    lines = [f'| split | method | seeds | method - {REFERENCE} | headroom ({BOUND} - '
             f'{REFERENCE}) | share of headroom recovered |', '|---|---|---|---|---|---|']
    for row in rows:
        share = f'{row["recovered"]:.2f}' if 'recovered' in row else '-'
        lines.append(f'| {row["split"]} | {row["method"]} | {row["seeds"]} | '
                     f'{_pm(row, "gain", 1)} | {_pm(row, "headroom", 1)} | {share} |')
    return '\n'.join(lines)


def _pm(row: dict[str, Any], metric: str, digits: int) -> str:
    """Table cell `mean ± s.e.` of `metric` (its `_se` beside it in the row); '-' without it."""
    if metric not in row:
        return '-'
    return f'{row[metric]:.{digits}f} ± {row[metric + "_se"]:.{digits}f}'


def diagnostics_table(rows: list[dict[str, Any]]) -> str:
    """Markdown: the adaptation diagnostics per method and split (mean ± s.e. over seeds)."""
    lines = ['| method | split | seeds | context sensitivity (mean abs. delta action) | '
             'context spread / noise | value of adaptation (frozen to other extreme) | '
             'value of adaptation (frozen to mean) | value of adaptation (frozen to the train '
             "values' mean) | value of adaptation (the same, frozen once the history is full) |",
             '|---|---|---|---|---|---|---|---|---|']
    for row in rows:
        lines.append(f'| {row["method"]} | {row["split"]} | {row["seeds"]} | '
                     f'{_pm(row, "sensitivity", 3)} | {_pm(row, "spread_noise", 2)} | '
                     f'{_pm(row, "adaptation_value_other", 1)} | '
                     f'{_pm(row, "adaptation_value_mean", 1)} | '
                     f'{_pm(row, "adaptation_value_train_mean", 1)} | '
                     f'{_pm(row, "adaptation_value_steady", 1)} |')
    return '\n'.join(lines)


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The results table as markdown (returns to one decimal, Spearman to two)."""
    lines = ['| method | split | seeds | return | return, switching episode | '
             'adaptation latency (steps) | Spearman | random policy |',
             '|---|---|---|---|---|---|---|---|']
    for row in rows:
        random = f'{row["random_return"]:.1f}' if 'random_return' in row else '-'
        lines.append(f'| {row["method"]} | {row["split"]} | {row["seeds"]} | '
                     f'{_pm(row, "mean_return", 1)} | '
                     f'{_pm(row, "switching_return", 1)} | '
                     f'{_pm(row, "mean_latency", 1)} | {_pm(row, "spearman", 2)} | '
                     f'{random} |')
    return '\n'.join(lines)


def wall_time_table(runs: list[dict[str, Any]]) -> str:
    """Markdown: per method and seed, training seconds + evaluation seconds (all splits).

    A run resumed from a shorter one shows both training pieces (earlier + this one).
    """
    cells: dict[str, dict[int, str]] = defaultdict(dict)
    evals: dict[tuple[str, int], float] = defaultdict(float)
    for run in runs:
        evals[(run['method'], run['seed'])] += float(run['eval_seconds'] or 0)
    for run in runs:
        train = str(run['train_seconds'] or '?')
        if run.get('earlier_train_seconds'):
            train = f'({run["earlier_train_seconds"]} + {train})'
        cells[run['method']][run['seed']] = f'{train} + {evals[(run["method"], run["seed"])]:.0f}'
    seeds = sorted({run['seed'] for run in runs})
    lines = ['| method | ' + ' | '.join(f'seed {s}' for s in seeds) + ' |',
             '|---|' + '---|' * len(seeds)]
    for method in sorted(cells, key=method_order_key):
        lines.append(f'| {method} | ' + ' | '.join(cells[method].get(s, '-') for s in seeds)
                     + ' |')
    return '\n'.join(lines)


def _plot(rows: list[dict[str, Any]], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    methods = sorted({row['method'] for row in rows}, key=method_order_key)
    splits = sorted({row['split'] for row in rows}, key=lambda s: _rank(s, SPLIT_ORDER))
    lookup = {(row['method'], row['split']): row for row in rows}
    fig, ax = plt.subplots(figsize=(9, 4))
    width = 0.8 / max(len(methods), 1)
    for i, method in enumerate(methods):
        cells = [lookup.get((method, split), {}) for split in splits]
        ax.bar(np.arange(len(splits)) + i * width,
               [c.get('mean_return', np.nan) for c in cells], width,
               yerr=[c.get('mean_return_se', 0.0) for c in cells], label=method, capsize=3)
    ax.set_xticks(np.arange(len(splits)) + width * (len(methods) - 1) / 2, splits)
    ax.set_ylabel('episode return (mean ± s.e. over seeds)')
    ax.set_title(title)
    ax.legend(fontsize=8, loc='upper left', bbox_to_anchor=(1.0, 1.0))  # never over a bar
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(folder: Path, out: Path, title: str | None = None) -> list[dict[str, Any]]:
    """Aggregate `folder`; write summary.csv, runs.csv, table.md, wall_times.md, returns.png."""
    rows = per_method(folder)
    if not rows:
        raise ReportError(f'{folder}: no finished evaluations in it or any folder below it '
                          '(an eval.json beside summary.csv, as `zeus eval` writes, or '
                          '<method>_s<seed>/eval_<split>/ finished in <method>_s<seed>/state.json '
                          'or by an eval_<split>/.done marker)')
    out.mkdir(parents=True, exist_ok=True)
    fields = ['method', 'split', 'seeds'] + [f for m in METRICS for f in (m, f'{m}_se')]
    with (out / 'summary.csv').open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=[*fields, 'random_return'])
        writer.writeheader()
        writer.writerows(rows)
    with (out / 'runs.csv').open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=['method', 'seed', 'split', *METRICS,
                                                    'train_seconds', 'earlier_train_seconds',
                                                    'eval_seconds'])
        writer.writeheader()
        runs = per_run(folder)
        writer.writerows(runs)
    (out / 'wall_times.md').write_text(wall_time_table(runs) + '\n')
    (out / 'table.md').write_text(markdown_table(rows) + '\n')
    (out / 'diagnostics.md').write_text(diagnostics_table(rows) + '\n')
    headroom = headroom_rows(runs)
    if headroom:
        with (out / 'headroom.csv').open('w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=['split', 'method', 'seeds', 'gain',
                                                        'gain_se', 'headroom', 'headroom_se',
                                                        'recovered'])
            writer.writeheader()
            writer.writerows(headroom)
        (out / 'headroom.md').write_text(headroom_table(headroom) + '\n')
    _plot(rows, task_label(title or folder.name), out / 'returns.png')
    return rows
