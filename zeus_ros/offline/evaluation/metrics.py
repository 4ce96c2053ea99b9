"""Metric tables as CSV and PNG: one place for the files that training and evaluation write.

Rows are plain dicts; a key may be missing from some rows (the actor loss exists only every
`actor_update_freq` updates, evaluation columns only at evaluation steps), so CSVs hold the
union of the columns and leave missing cells empty.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from zeus_ros.atomic_file import atomic_write

__all__ = ['MetricsLog', 'RunningMean', 'format_table', 'metric_series', 'overlap_style',
           'plot_bars', 'plot_grouped_lines', 'plot_heatmaps', 'plot_metric_grid', 'plot_trace',
           'pyplot', 'read_csv', 'write_csv']


def _columns(rows: Iterable[Mapping[str, Any]]) -> list[str]:
    """Union of the keys of `rows`, in first-seen order."""
    seen: dict[str, None] = {}
    for row in rows:
        for key in row:
            seen.setdefault(key, None)
    return list(seen)


def _cell(value: Any) -> Any:
    """Floats written compactly; None and NaN become empty cells."""
    if value is None:
        return ''
    if isinstance(value, float):
        return '' if math.isnan(value) else f'{value:.6g}'
    return value


def write_csv(path: str | Path, rows: Sequence[Mapping[str, Any]],
              columns: Sequence[str] | None = None) -> Path:
    """Write `rows` atomically, so readers never see half.

    Columns: `columns` (then a file without rows still has its header), else the union of the
    rows' keys.
    """
    path = Path(path)
    columns = list(columns) if columns is not None else _columns(rows)
    with atomic_write(path, 'w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({key: _cell(row.get(key)) for key in columns})
    return path


def _parse(text: str) -> Any:
    """CSV cell back to a number where it is one; empty cells become None."""
    if text == '':
        return None
    try:
        number = float(text)
    except ValueError:
        return text
    return int(number) if number.is_integer() and '.' not in text and 'e' not in text else number


def read_csv(path: str | Path) -> list[dict[str, Any]]:
    """Rows of a CSV written by `write_csv`, numbers parsed, empty cells left out."""
    with Path(path).open(newline='') as handle:
        return [{key: value for key, value in ((k, _parse(v)) for k, v in row.items())
                 if value is not None} for row in csv.DictReader(handle)]


class RunningMean:
    """Per-key means over a logging window; keys may come and go between updates."""

    def __init__(self) -> None:
        self._sum: dict[str, float] = {}
        self._count: dict[str, int] = {}

    def add(self, values: Mapping[str, float]) -> None:
        """Accumulate one update's metrics."""
        for key, value in values.items():
            self._sum[key] = self._sum.get(key, 0.0) + float(value)
            self._count[key] = self._count.get(key, 0) + 1

    def pop(self) -> dict[str, float]:
        """The window's means; starts a new window."""
        means = {key: self._sum[key] / self._count[key] for key in self._sum}
        self._sum.clear()
        self._count.clear()
        return means


class MetricsLog:
    """Rows kept in memory and rewritten to one CSV on every flush (runs log ~100s of rows)."""

    def __init__(self, path: str | Path, rows: list[dict[str, Any]] | None = None) -> None:
        self.path = Path(path)
        self.rows: list[dict[str, Any]] = list(rows or [])

    @classmethod
    def resume(cls, path: str | Path, *, up_to_step: int) -> MetricsLog:
        """Rows on disk up to `up_to_step` (later ones belong to a lost tail of the run)."""
        path = Path(path)
        rows = read_csv(path) if path.is_file() else []
        return cls(path, [row for row in rows if int(row.get('step', 0)) <= up_to_step])

    def append(self, row: Mapping[str, Any]) -> None:
        """Add one row (written at the next flush)."""
        self.rows.append(dict(row))

    def flush(self) -> Path:
        """Rewrite the CSV with every row."""
        return write_csv(self.path, self.rows)


OVERLAP_MARKERS = ('o', 's', '^', 'v', 'D', 'x', '+', '*')
OVERLAP_STYLES = ('-', '--', '-.', ':')
"""Marker and dash per line of one plot, so coinciding lines stay distinguishable."""


def overlap_style(index: int, count: int) -> dict[str, Any]:
    """Matplotlib line keywords for line `index` of `count`, so lines that coincide stay visible.

    Each line gets its own marker and dash, and later lines are drawn thinner with smaller
    markers on top of the earlier ones (e.g. several methods at return 0).
    """
    share = index / max(count, 1)
    return {'marker': OVERLAP_MARKERS[index % len(OVERLAP_MARKERS)], 'ms': 7 - 4 * share,
            'ls': OVERLAP_STYLES[index % len(OVERLAP_STYLES)], 'lw': 2.2 - 1.4 * share,
            'alpha': 0.85}


def pyplot() -> Any:
    """Matplotlib with the file-only backend (no display on robots and CI)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


FEW_POINTS = 30
"""Curves with fewer points than this get a marker at each: one point alone draws no line."""


def metric_series(rows: Sequence[Mapping[str, Any]], keys: Sequence[str], x: str = 'step'
                  ) -> tuple[list[tuple[str, tuple[float, ...], tuple[float, ...]]], list[str],
                             list[str]]:
    """What plot_metric_grid draws: curves, one-value lines, keys without data.

    Curves: (key, xs, ys) of keys with two or more finite values; one-value lines:
    'key = v  (step s)'; without data: keys logged with no finite value (NaN only).
    """
    curves, single, empty = [], [], []
    for key in keys:
        pairs = [(row[x], row[key]) for row in rows if key in row and x in row
                 and isinstance(row[key], int | float) and math.isfinite(row[key])]
        if len(pairs) > 1:
            curves.append((key, *zip(*pairs, strict=True)))
        elif pairs:
            single.append(f'{key} = {pairs[0][1]:.4g}  ({x} {pairs[0][0]:g})')
        elif any(key in row for row in rows):
            empty.append(key)
    return curves, single, empty


def plot_metric_grid(rows: Sequence[Mapping[str, Any]], keys: Sequence[str], path: str | Path,
                     *, x: str = 'step', title: str = '') -> Path | None:
    """One small panel per metric key with a curve against `x`; None when no key has data.

    Only keys with two or more finite values get a panel (a short run logs each key once: 13
    empty-looking panels); the rest are listed in one compact text panel, with their single
    value or as 'no data' (NaN only).
    """
    curves, single, empty = metric_series(rows, keys, x)
    if not (curves or single or empty):
        return None
    notes = (['one value each so far (a curve needs two logged values):', *single]
             if single else []) + ([f'no data (NaN only): {", ".join(empty)}'] if empty else [])
    panels = len(curves) + bool(notes)
    plt = pyplot()
    cols = min(3, panels)
    nrows = math.ceil(panels / cols)
    height = 2.8 * nrows if curves else 0.7 + 0.16 * len(notes)
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols if curves else 6.0, height),
                             squeeze=False)
    for ax, (key, xs, ys) in zip(axes.flat, curves, strict=False):
        few = {'marker': 'o', 'ms': 3} if len(xs) < FEW_POINTS else {}
        ax.plot(xs, ys, lw=1.2, **few)
        ax.set_title(f'{key} (last {ys[-1]:.3g})', fontsize=9)
        ax.set_xlabel('update' if x == 'step' else x, fontsize=8)
        ax.set_ylabel(key.rsplit('/', 1)[-1], fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    spare = list(axes.flat)[len(curves):]
    for ax in spare:
        ax.set_visible(False)
    if notes:
        spare[0].set_visible(True)
        spare[0].axis('off')
        spare[0].text(0.0, 1.0, '\n'.join(notes), va='top', ha='left', fontsize=7,
                      family='monospace', transform=spare[0].transAxes, wrap=True)
    if title:
        fig.suptitle(title, fontsize=10)
    # Leave the top strip to the figure title, so it never overlaps a panel title.
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 1.0 - 0.3 / height if title else 1.0))
    return _save(fig, path)


def plot_grouped_lines(rows: Sequence[Mapping[str, Any]], *, x: str, y: str, group: str,
                       path: str | Path, title: str = '', ylabel: str = '') -> Path | None:
    """One line of `y` against `x` per distinct `group` value (e.g. return per context)."""
    groups: dict[Any, list[tuple[float, float]]] = {}
    for row in rows:
        if x in row and y in row and group in row:
            groups.setdefault(row[group], []).append((row[x], row[y]))
    if not groups:
        return None
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    cmap = plt.get_cmap('viridis')
    keys = sorted(groups, key=lambda g: (not isinstance(g, int | float), g))
    for index, key in enumerate(keys):
        points = sorted(groups[key])
        color = cmap(index / max(len(keys) - 1, 1))
        ax.plot(*zip(*points, strict=True), color=color, **overlap_style(index, len(keys)),
                label=f'{group}={key:g}' if isinstance(key, float) else f'{group}={key}')
    ax.set_xlabel('update' if x == 'step' else x)
    ax.set_ylabel(ylabel or y)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.0, 1.0))  # never over a line
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_heatmaps(matrices: Mapping[str, np.ndarray], labels: Sequence[str], path: str | Path,
                  *, title: str = '', axis_label: str = '', units: Sequence[str] = ()) -> Path:
    """Side-by-side heat maps of square matrices sharing axis labels (pairwise distances).

    `axis_label` names what the rows and columns are (e.g. 'torso_length [m]'), `units[i]`
    what the colour of matrix i measures (e.g. 'distance [m]').
    """
    plt = pyplot()
    fig, axes = plt.subplots(1, len(matrices), figsize=(4.6 * len(matrices), 4.3),
                             squeeze=False)
    for index, (ax, (name, matrix)) in enumerate(zip(axes.flat, matrices.items(), strict=True)):
        image = ax.imshow(matrix, cmap='magma')
        ax.set_title(name, fontsize=9)
        ax.set_xticks(range(len(labels)), labels, rotation=90, fontsize=7)
        ax.set_yticks(range(len(labels)), labels, fontsize=7)
        ax.set_xlabel(axis_label, fontsize=8)
        ax.set_ylabel(axis_label, fontsize=8)
        fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04,
                     label=units[index] if index < len(units) else '')
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.93 if title else 1.0))
    return _save(fig, path)


def _save(fig: Any, path: str | Path) -> Path:
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def format_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> str:
    """A fixed-width text table (numbers to 4 significant digits) for the terminal."""
    def text(value: Any) -> str:
        if value is None or (isinstance(value, float) and math.isnan(value)):
            return '-'
        return f'{value:.4g}' if isinstance(value, float) else str(value)

    cells = [[text(row.get(col)) for col in columns] for row in rows]
    widths = [max([len(col), *(len(r[i]) for r in cells)]) for i, col in enumerate(columns)]
    lines = ['  '.join(col.rjust(w) for col, w in zip(columns, widths, strict=True))]
    lines += ['  '.join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    return '\n'.join(lines)


PANELS_PER_ROW = 4
"""Grids of small panels wrap after this many, so a figure stays readable at any count."""


def plot_bars(labels: Sequence[str], series: Mapping[str, Sequence[float]], path: str | Path,
              *, xlabel: str = '', ylabel: str = '', title: str = '') -> Path:
    """One panel per label (e.g. context value), a bar per series (agent, frozen, random).

    Panels wrap after PANELS_PER_ROW and share the y axis and one legend: a row of grouped
    bars grew 0.6 in per bar (3168 px wide for 8 values of 6 policies).
    """
    plt = pyplot()
    cols = max(1, min(PANELS_PER_ROW, len(labels)))
    nrows = max(1, math.ceil(len(labels) / cols))
    width = max(6.0, 0.6 + 2.9 * cols)
    ncol = max(1, min(len(series), int(width // 1.6)))
    legend_h, title_h = 0.3 * math.ceil(len(series) / ncol) + 0.1, 0.4 if title else 0.0
    height = 2.4 * nrows + legend_h + title_h
    fig, axes = plt.subplots(nrows, cols, figsize=(width, height), sharey=True, squeeze=False)
    colors = [plt.get_cmap('tab10')(i % 10) for i in range(len(series))]
    for index, ax in enumerate(axes.flat):
        if index >= len(labels):
            ax.set_visible(False)
            continue
        heights = [values[index] for values in series.values()]
        ax.bar(range(len(series)), heights, 0.8, color=colors)
        ax.axhline(0.0, color='black', lw=0.6)
        ax.set_xticks([])
        ax.set_title(f'{xlabel} = {labels[index]}' if xlabel else labels[index], fontsize=9)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3, axis='y')
        if index % cols == 0:
            ax.set_ylabel(ylabel, fontsize=8)
    handles = [plt.Rectangle((0, 0), 1, 1, color=color) for color in colors]
    fig.legend(handles, list(series), loc='lower center', ncol=ncol, fontsize=8, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)
    # The top strip for the title, the bottom one for the legend: never over a panel.
    fig.tight_layout(rect=(0.0, legend_h / height, 1.0, 1.0 - title_h / height))
    return _save(fig, path)


def plot_trace(values: Sequence[float], others: Mapping[str, Sequence[float]], *,
               marks: Sequence[int], path: str | Path, title: str = '') -> Path:
    """A per-step trace with vertical marks (e.g. context switches) and extra lower panels."""
    plt = pyplot()
    fig, axes = plt.subplots(1 + len(others), 1, figsize=(8.0, 2.4 * (1 + len(others))),
                             sharex=True, squeeze=False)
    panels = [('per-step reward', values), *others.items()]
    for ax, (name, ys) in zip(axes[:, 0], panels, strict=True):
        ax.plot(np.arange(len(ys)), ys, lw=0.9)
        for mark in marks:
            ax.axvline(mark, color='tab:red', lw=0.8, alpha=0.6)
        ax.set_ylabel(name, fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel('control step')
    if title:
        axes[0, 0].set_title(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)
