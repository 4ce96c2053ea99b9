"""Aggregate `zeus eval` summaries of an experiment folder: mean and standard error over seeds.

    python experiments/summarize.py runs/exp/cheetah_run_v0 --out docs/results/cheetah_run_v0

Reads <folder>/<method>_s<seed>/eval_<split>/summary.csv, writes a CSV and a PNG of returns
per method and split, and prints a markdown table (as pasted into docs/results.md).
"""

from __future__ import annotations

import argparse
from collections import defaultdict
import csv
from pathlib import Path
import re

import numpy as np

METRICS = ('mean_return', 'switching_return', 'mean_latency', 'spearman')
RUN_NAME = re.compile(r'^(?P<method>.+)_s(?P<seed>\d+)$')


def collect(folder: Path) -> dict[tuple[str, str], dict[str, list[float]]]:
    """(method, split) -> metric -> one value per finished seed."""
    table: dict[tuple[str, str], dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for summary in sorted(folder.glob('*/eval_*/summary.csv')):
        match = RUN_NAME.match(summary.parent.parent.name)
        if match is None or not (summary.parent / '.done').exists():
            continue
        for row in csv.DictReader(summary.open()):
            if row['policy'] != 'agent':
                continue
            key = (match['method'], row['split'])
            for metric in METRICS:
                if row.get(metric):
                    table[key][metric].append(float(row[metric]))
            table[key]['seeds'].append(float(match['seed']))
    return table


def mean_se(values: list[float]) -> tuple[float, float]:
    """Mean and standard error (0 for a single value)."""
    array = np.asarray(values, dtype=np.float64)
    se = float(array.std(ddof=1) / np.sqrt(len(array))) if len(array) > 1 else 0.0
    return float(array.mean()), se


def main() -> None:
    """Print the markdown table; write CSV and PNG."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('folder', type=Path)
    parser.add_argument('--out', type=Path, required=True)
    args = parser.parse_args()
    table = collect(args.folder)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for (method, split), metrics in sorted(table.items()):
        row = {'method': method, 'split': split, 'seeds': len(metrics['seeds'])}
        for metric in METRICS:
            if metrics.get(metric):
                row[metric], row[f'{metric}_se'] = mean_se(metrics[metric])
        rows.append(row)
    fields = ['method', 'split', 'seeds'] + [f for m in METRICS for f in (m, f'{m}_se')]
    with (args.out / 'summary.csv').open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)

    def cell(row: dict, metric: str, digits: int) -> str:
        if metric not in row:
            return '-'
        return f'{row[metric]:.{digits}f} ± {row[metric + "_se"]:.{digits}f}'

    print('| method | split | seeds | return | return, switch every 100 steps | '
          'adaptation latency (steps) | Spearman |')
    print('|---|---|---|---|---|---|---|')
    for row in rows:
        print(f'| {row["method"]} | {row["split"]} | {row["seeds"]} | '
              f'{cell(row, "mean_return", 1)} | {cell(row, "switching_return", 1)} | '
              f'{cell(row, "mean_latency", 1)} | {cell(row, "spearman", 2)} |')

    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    methods = sorted({row['method'] for row in rows})
    splits = sorted({row['split'] for row in rows})
    fig, ax = plt.subplots(figsize=(7, 4))
    width = 0.8 / max(len(methods), 1)
    for i, method in enumerate(methods):
        means = [next((r['mean_return'] for r in rows if r['method'] == method
                       and r['split'] == s), np.nan) for s in splits]
        errors = [next((r['mean_return_se'] for r in rows if r['method'] == method
                        and r['split'] == s), 0.0) for s in splits]
        ax.bar(np.arange(len(splits)) + i * width, means, width, yerr=errors, label=method,
               capsize=3)
    ax.set_xticks(np.arange(len(splits)) + width * (len(methods) - 1) / 2, splits)
    ax.set_ylabel('return per 500-step episode (mean ± s.e. over seeds)')
    ax.set_title(args.folder.name)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out / 'returns.png', dpi=110)
    plt.close(fig)


if __name__ == '__main__':
    main()
