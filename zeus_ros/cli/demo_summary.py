"""The demo's value of adaptation: live against frozen context, paired per segment and seed.

Separate from demo.py (which runs processes) so the arithmetic and the picture are testable
without ROS. A segment is one stretch of constant true context; the live and the frozen run of a
schedule seed meet the same segments with the same initial states, so their per-segment returns
pair up.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ['AdaptationRow', 'adaptation_rows', 'plot_adaptation', 'summarize_adaptation',
           'write_rows']


@dataclass(frozen=True)
class AdaptationRow:
    """One segment of one schedule seed, in both runs."""

    seed: int
    segment: int
    context: tuple[float, ...]
    in_training_range: bool
    live: float
    frozen: float

    @property
    def gain(self) -> float:
        """What adapting earned over the frozen context in this segment."""
        return self.live - self.frozen


def adaptation_rows(seed: int, live: Sequence[Any], frozen: Sequence[Any],
                    train_values: Sequence[Sequence[float]], min_steps: int = 1
                    ) -> list[AdaptationRow]:
    """Pair the SegmentSummary lists of one seed's two runs.

    Dropped: segments cut short in either run, and segments under `min_steps` (the run's last
    step opening a new segment).
    """
    frozen_by_segment = {s.segment: s for s in frozen}
    train = {tuple(round(v, 9) for v in value) for value in train_values}
    rows = []
    for seg in live:
        other = frozen_by_segment.get(seg.segment)
        if (other is None or other.steps != seg.steps or not seg.context
                or seg.steps < min_steps):
            continue
        context = tuple(float(v) for v in seg.context)
        rows.append(AdaptationRow(seed, seg.segment, context,
                                  tuple(round(v, 9) for v in context) in train,
                                  float(seg.total_return), float(other.total_return)))
    return rows


def _mean_se(values: Sequence[float]) -> tuple[float, float, int]:
    """report.mean_se with the count; the s.e. of fewer than two values is NaN (not shown)."""
    from zeus_ros.offline.evaluation.report import mean_se

    if not len(values):
        return float('nan'), float('nan'), 0
    mean, se = mean_se(list(values))
    return mean, (se if len(values) > 1 else float('nan')), len(values)


def summarize_adaptation(rows: Sequence[AdaptationRow], every: int) -> tuple[dict[str, Any], str]:
    """Mean ± s.e. of the per-segment gain (all, training values, beyond), and one sentence.

    The standard error is over segments pooled across seeds; per-seed totals are reported too,
    since segments of one run share a policy state and are not fully independent.
    """
    groups: Mapping[str, Sequence[AdaptationRow]] = {
        'all': rows, 'train': [r for r in rows if r.in_training_range],
        'beyond': [r for r in rows if not r.in_training_range]}
    stats = {name: _mean_se([r.gain for r in group]) for name, group in groups.items()}
    seeds = sorted({r.seed for r in rows})
    totals = [sum(r.gain for r in rows if r.seed == seed) for seed in seeds]
    per_seed = _mean_se(totals)
    summary = {'stats': stats, 'seeds': seeds, 'seed_totals': totals, 'per_seed': per_seed}
    mean, se, n = stats['all']
    if not n:
        return summary, 'No segment ran to the end in both runs: no value of adaptation.'
    sign = 'more' if mean >= 0 else 'less'
    parts = [f'Adapting earned {abs(mean):.1f} ± {se:.1f} {sign} return per {every}-step '
             f'segment than the same policy with its context frozen at its training mean '
             f'({n} segments over {len(seeds)} schedule seed(s), paired; '
             f'{_verdict(mean, se)})']
    for name, label in (('train', 'on training values'), ('beyond', 'beyond the training range')):
        m, s, k = stats[name]
        if k:
            spread = f' ± {s:.1f}' if np.isfinite(s) else ''
            parts.append(f'{label} {m:+.1f}{spread} ({k} segment{"s" if k > 1 else ""})')
    return summary, '; '.join(parts) + '.'


def _verdict(mean: float, se: float) -> str:
    if not np.isfinite(se) or se == 0:
        return 'one segment: no standard error'
    ratio = mean / se
    return (f'{ratio:.1f} standard errors' + (', more than chance' if abs(ratio) > 2
                                                else ', within chance'))


def write_rows(rows: Sequence[AdaptationRow], names: Sequence[str], path: Path) -> Path:
    """value_of_adaptation.csv: one row per seed and segment."""
    header = ['seed', 'segment', *(f'true_{n}' for n in names), 'in_training_range',
              'return_live', 'return_frozen', 'gain']
    lines = [','.join(header)]
    for r in rows:
        lines.append(','.join([str(r.seed), str(r.segment), *(f'{v:g}' for v in r.context),
                               str(r.in_training_range).lower(), f'{r.live:.4f}',
                               f'{r.frozen:.4f}', f'{r.gain:.4f}']))
    path.write_text('\n'.join(lines) + '\n')
    return path


def plot_adaptation(rows: Sequence[AdaptationRow], names: Sequence[str], path: Path,
                    title: str) -> Path:
    """Per-segment gain against the true context (training values and beyond marked)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4), width_ratios=(2, 1))
    xs = np.array([r.context[0] for r in rows]) if rows else np.zeros(0)
    gains = np.array([r.gain for r in rows])
    inside = np.array([r.in_training_range for r in rows], dtype=bool)
    for mask, label, color in ((inside, 'training values', 'tab:blue'),
                               (~inside, 'beyond the training range', 'tab:orange')):
        if mask.any():
            left.scatter(xs[mask], gains[mask], s=18, alpha=0.7, color=color, label=label)
    left.axhline(0.0, color='black', lw=0.8)
    left.set_xlabel(f'true {names[0] if names else "context"}')
    left.set_ylabel('segment return: live - frozen')
    left.legend(loc='best', fontsize=8)
    left.set_title('every segment of every seed')
    labels, means, errors = [], [], []
    for name, keep in (('training', inside), ('beyond', ~inside)):
        if keep.any():
            values = gains[keep]
            labels.append(f'{name}\n(n={keep.sum()})')
            means.append(values.mean())
            errors.append(values.std(ddof=1) / np.sqrt(len(values)) if len(values) > 1 else 0)
    right.bar(labels, means, yerr=errors, capsize=6, color=['tab:blue', 'tab:orange'][:len(means)])
    right.axhline(0.0, color='black', lw=0.8)
    right.set_title('mean ± s.e. per segment')
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
