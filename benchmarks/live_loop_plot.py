"""CSV and pictures of bench_live_loop.py's rows: the targets, and where a live step's time goes.

`plot_targets` draws, per observation kind, each mode's ratio to the in-process rate and its
observation -> action p99 against issue 14's targets, one dot per round and the mean as a bar.

`plot_segments` draws, per observation kind, one bar per mode (mean over its rounds) cut into
the estimator's, the policy's and sim_bridge's segments of the live step, each beside the same
node's work in the in-process loop: what is left of a segment beyond its in-process part is
what the messages between the nodes cost (delivery, wake-ups, conversion, publishing).
"""

from __future__ import annotations

from collections.abc import Sequence
import csv
from pathlib import Path
from typing import Any

import numpy as np

COLOURS = {'estimator': '#4c72b0', 'policy': '#dd8452', 'sim_bridge': '#55a868'}


def write_rows(rows: Sequence[dict[str, Any]], path: Path) -> None:
    """Every row with every column any row has (empty where a row lacks it)."""
    columns = list(dict.fromkeys(key for row in rows for key in row))
    with path.open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, restval='')
        writer.writeheader()
        writer.writerows(rows)


def _mean(rows: Sequence[dict[str, Any]], key: str) -> float:
    return float(np.mean([row[key] for row in rows]))


def _label(row: dict[str, Any]) -> tuple[str, str]:
    """(mode, with its context lag when there is one; executor): one bar of the picture."""
    return row['mode'] + (f'/lag{row["lag"]}' if row['lag'] else ''), row['executor']


def plot_targets(rows: Sequence[dict[str, Any]], ratio_targets: dict[tuple[str, str], float],
                 p99_targets: dict[str, float], path: Path) -> None:
    """Ratio and p99 of each (kind, mode) against its target: bars are means, dots rounds."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    kinds = list(dict.fromkeys(row['kind'] for row in rows))
    figure, axes = plt.subplots(len(kinds), 2, figsize=(10, 1.5 + 2.2 * len(kinds)),
                                squeeze=False)
    for (ratio_axis, p99_axis), kind in zip(axes, kinds, strict=True):
        labels = list(dict.fromkeys(_label(row) for row in rows if row['kind'] == kind))
        for x, bar in enumerate(labels):
            same = [row for row in rows if row['kind'] == kind and _label(row) == bar]
            mode = same[0]['mode']
            for axis, key, target in ((ratio_axis, 'ratio', ratio_targets.get((kind, mode))),
                                      (p99_axis, 'p99', p99_targets.get(kind))):
                values = [float(row[key]) for row in same if np.isfinite(float(row[key]))]
                if not values:
                    continue
                mean = float(np.mean(values))
                met = target is None or (mean >= target if key == 'ratio' else mean <= target)
                axis.bar(x, mean, color='#55a868' if met else '#c44e52', alpha=0.6)
                axis.plot([x] * len(values), values, 'k.', markersize=5)
                if target is not None:
                    axis.plot([x - 0.4, x + 0.4], [target, target], 'k--', linewidth=1)
        for axis, title in ((ratio_axis, 'live / in-process rate (higher is better)'),
                            (p99_axis, 'observation -> action p99, ms (lower is better)')):
            axis.set_xticks(range(len(labels)), [label for label, _ in labels], fontsize=8)
            axis.set_title(f'{kind}: {title}', fontsize=9)
    figure.suptitle('issue 14 targets (dashed); green: mean meets it, red: misses it; '
                    'dots: rounds', fontsize=9)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def plot_segments(rows: Sequence[dict[str, Any]], segments: Sequence[str], path: Path) -> None:
    """Stacked bars: in-process part and live segment of each node, per kind and mode."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    split = [row for row in rows if f'seg_{segments[0]}_mean' in row]
    kinds = list(dict.fromkeys(row['kind'] for row in split))
    figure, axes = plt.subplots(len(kinds), 1, figsize=(9, 1.2 + 1.6 * len(kinds)),
                                squeeze=False)
    for axis, kind in zip(axes[:, 0], kinds, strict=True):
        labels = list(dict.fromkeys(_label(row) for row in split if row['kind'] == kind))
        for y, bar in enumerate(labels):
            same = [row for row in split if row['kind'] == kind and _label(row) == bar]
            left = 0.0
            for name in segments:
                live, local = _mean(same, f'seg_{name}_mean'), _mean(same,
                                                                     f'in_process_{name}_mean')
                axis.barh(y, local, left=left, color=COLOURS.get(name), edgecolor='black',
                          label=f'{name}: its work in-process' if y == 0 else None)
                axis.barh(y, max(live - local, 0.0), left=left + local, color=COLOURS.get(name),
                          alpha=0.35, edgecolor='black', hatch='//',
                          label=f'{name}: beyond it, live' if y == 0 else None)
                left += max(live, local)
            axis.text(left, y, f' {left:.2f} ms ({len(same)} round(s))', va='center',
                      fontsize=8)
        axis.set_yticks(range(len(labels)), [f'{label} ({executor})'
                                             for label, executor in labels])
        axis.set_title(f'{kind}: one live step, cut where each node publishes (mean ms)',
                       fontsize=10)
        axis.set_xlabel('ms per step')
        axis.margins(x=0.15)
    axes[0, 0].legend(fontsize=7, ncol=3, loc='upper center', bbox_to_anchor=(0.5, -0.35))
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
