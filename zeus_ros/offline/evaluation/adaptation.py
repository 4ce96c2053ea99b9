"""Does a checkpoint adapt? Its value of adaptation next to the zoo's, paired, in one command.

    zeus adaptation --checkpoint runs/bias/run/final.pt

For each checkpoint: mean return on the family's train and beyond-range values, and the value of
adaptation there: return with the context live minus the same episodes with the context frozen
at the checkpoint's own training-mean context (same initial states, paired per value and
episode; mean ± s.e. over the values), plus the context sensitivity (mean |delta action| when
psi of one extreme train value replaces the other's). The family's zoo checkpoint is measured
the same way beside it (--against none skips it). scripts/build_zoo.py writes the zoo's cards
with this function.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ['AdaptationReport', 'format_reports', 'measure_adaptation']

EVAL_SEED = 200
"""Initial states that chose nothing: the archive cards and the zoo's choice used seed 100."""
MEASURED_SPLITS = ('train', 'extrapolation')
"""Where adapting is reported: the training values and beyond the range (of sim_bridge SPLITS)."""


@dataclass
class AdaptationReport:
    """What one checkpoint earns and what adapting adds, per split (mean ± s.e. over values)."""

    checkpoint: Path
    task: str
    method: str
    returns: dict[str, tuple[float, float]] = field(default_factory=dict)
    adaptation: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Live minus frozen at the training-mean context; empty without a context."""
    sensitivity: float = float('nan')


def _per_value(rows: Sequence[dict[str, Any]], episodes: int) -> np.ndarray:
    returns = np.array([row['return'] for row in rows], dtype=float)
    return returns.reshape(-1, episodes).mean(axis=1)


def measure_adaptation(checkpoint: Path, *, episodes: int = 3, seed: int = EVAL_SEED,
                       splits: Sequence[str] = MEASURED_SPLITS, progress: bool = True,
                       expect_sha256: str | None = None, label: str = ''
                       ) -> AdaptationReport:
    """Returns and value of adaptation of one checkpoint on its family's splits.

    `expect_sha256`: refuse the file unless it has this sha256 (zeus_ros/integrity.py).
    Each progress bar says its pass, `LABEL pass i/N: what`: a bar that starts over is the
    next pass, not the same work again (issue 52).
    """
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.diagnostics import context_sensitivity
    from zeus_ros.offline.evaluation.evaluate import (
        evaluate_contexts,
        overall_mean_context,
        split_values,
    )
    from zeus_ros.offline.evaluation.report import mean_se

    agent = InferenceAgent.from_checkpoint(checkpoint, expect_sha256=expect_sha256)
    report = AdaptationReport(Path(checkpoint), agent.task, agent.method)
    desc = pass_names(splits, bool(agent.context_dim), label)
    train_mean = None
    if agent.context_dim:
        traces: list[Any] = []
        values = split_values(agent.task, 'train')
        evaluate_contexts(agent, values, episodes=episodes, seed=seed, traces=traces,
                          progress=progress, desc=next(desc))
        train_mean = overall_mean_context(agent, traces)
        report.sensitivity = context_sensitivity(agent, traces, values)
    for split in splits:
        values = split_values(agent.task, split)
        live = _per_value(evaluate_contexts(agent, values, episodes=episodes, seed=seed,
                                            progress=progress, desc=next(desc)), episodes)
        report.returns[split] = mean_se(live)
        if train_mean is not None:
            frozen = _per_value(evaluate_contexts(
                agent, values, episodes=episodes, seed=seed, frozen=[train_mean] * len(values),
                progress=progress, desc=next(desc)), episodes)
            report.adaptation[split] = mean_se(live - frozen)
    return report


def pass_names(splits: Sequence[str], context: bool, label: str = '') -> Iterator[str]:
    """The progress-bar names of measure_adaptation's passes, in order: 'pass i/N: ...'.

    With a learned context: the train values (for the mean context), then per split the live
    and the frozen pass; without one, one pass per split.
    """
    names = (['train values (mean context)'] if context else []) + [
        f'{split} {kind}' for split in splits for kind in (('live', 'frozen') if context
                                                           else ('returns',))]
    prefix = f'{label} ' if label else ''
    for index, name in enumerate(names, 1):
        yield f'{prefix}pass {index}/{len(names)}: {name}'


def fmt(pair: tuple[float, float] | None) -> str:
    """'mean ± se', or '-' when not measured."""
    return '-' if pair is None else f'{pair[0]:.1f} ± {pair[1]:.1f}'


def format_reports(reports: Sequence[tuple[str, AdaptationReport]]) -> str:
    """A table, one row per checkpoint, and a sentence per learned-context checkpoint."""
    header = ['', 'method', *(f'return {s}' for s in MEASURED_SPLITS),
              *(f'adaptation {s}' for s in MEASURED_SPLITS), 'sensitivity']
    rows = [header]
    for label, r in reports:
        rows.append([label, r.method, *(fmt(r.returns.get(s)) for s in MEASURED_SPLITS),
                     *(fmt(r.adaptation.get(s)) for s in MEASURED_SPLITS),
                     '-' if np.isnan(r.sensitivity) else f'{r.sensitivity:.3f}'])
    widths = [max(len(row[i]) for row in rows) for i in range(len(header))]
    lines = ['  '.join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
             for row in rows]
    lines.insert(1, '-' * len(lines[0]))
    for label, r in reports:
        if 'extrapolation' in r.adaptation:
            m, se = r.adaptation['extrapolation']
            verdict = ('adapts: more than 2 s.e. above zero' if m > 2 * se else
                       'no adaptation measurable (within 2 s.e. of zero)' if m > -2 * se else
                       'its context hurts beyond the range (more than 2 s.e. below zero)')
            lines.append(f'{label}: beyond the training range, its live context earns '
                         f'{m:+.1f} ± {se:.1f} per episode over the same policy with the context '
                         f'frozen at its training mean: {verdict}.')
    return '\n'.join(lines)
