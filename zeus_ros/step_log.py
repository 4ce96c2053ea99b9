"""What `zeus inspect` and the demo show: per-step records, context segments, plots (no ROS)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
import math
from pathlib import Path

import numpy as np

__all__ = [
    'SeenStep',
    'SegmentSummary',
    'StepLog',
    'format_segments',
    'percentile',
    'plot_inspection',
]


@dataclass
class SeenStep:
    """Everything seen about one control step."""

    step: int
    episode: int = -1
    first: bool = False
    reward: float = 0.0
    truth: tuple[float, ...] | None = None
    segment: int = -1
    estimate: np.ndarray | None = None
    history_length: int = 0
    readout: tuple[float, ...] | None = None
    """The estimator's psi in the context's units (its calibrated read-out), when it has one."""
    novelty: tuple[float, float] | None = None
    """(score, threshold) of the estimator's novelty monitor; above: not a training context."""
    t_observation: float | None = None
    """When the middleware received the step's feedback (seconds, system clock)."""
    t_action: float | None = None
    """When the middleware received the action answering it (seconds, system clock)."""

    @property
    def latency_ms(self) -> float | None:
        """Observation-to-action latency as seen by the inspector."""
        if self.t_observation is None or self.t_action is None:
            return None
        return (self.t_action - self.t_observation) * 1e3


@dataclass
class SegmentSummary:
    """One stretch of constant true context: its values, length and return."""

    segment: int
    context: tuple[float, ...]
    first_step: int
    last_step: int
    steps: int
    total_return: float
    reward_per_step: float
    context_error: float | None = None
    """Mean distance of the estimate from its segment mean (spread of psi inside the segment)."""
    estimated: tuple[float, ...] | None = None
    """Mean read-out (estimate in the context's units) over the segment's steps with history."""
    novel: float | None = None
    """Share of the segment's scored steps above the novelty threshold."""


@dataclass
class StepLog:
    """Step records keyed by step index, in arrival order of their parts."""

    context_names: tuple[str, ...] = ()
    records: dict[int, SeenStep] = field(default_factory=dict)

    def record(self, step: int) -> SeenStep:
        """The record of `step`, created on first use."""
        if step not in self.records:
            self.records[step] = SeenStep(step)
        return self.records[step]

    def ordered(self) -> list[SeenStep]:
        """Records sorted by step index."""
        return [self.records[key] for key in sorted(self.records)]

    def segments(self) -> list[SegmentSummary]:
        """Per-context-segment summary: the return earned while each context was in force.

        The reward of step k was earned under the context of step k (the context that produced
        o_k), so it is credited to that segment; reset observations earn nothing.
        """
        summaries: list[SegmentSummary] = []
        current: list[SeenStep] = []

        def close() -> None:
            if not current:
                return
            rewards = [r.reward for r in current if not r.first]
            estimates = [r.estimate for r in current if r.estimate is not None
                         and r.estimate.size]
            error = None
            if estimates:
                stack = np.stack(estimates)
                error = float(np.linalg.norm(stack - stack.mean(0), axis=1).mean())
            total = float(np.sum(rewards)) if rewards else 0.0
            read = [r.readout for r in current if r.readout and r.history_length > 0]
            estimated = tuple(np.mean(read, axis=0).tolist()) if read else None
            scored = [r.novelty[0] > r.novelty[1] for r in current if r.novelty]
            novel = float(np.mean(scored)) if scored else None
            summaries.append(SegmentSummary(
                segment=current[0].segment, context=current[0].truth or (),
                first_step=current[0].step, last_step=current[-1].step, steps=len(current),
                total_return=total, reward_per_step=total / max(len(rewards), 1),
                context_error=error, estimated=estimated, novel=novel))

        for record in self.ordered():
            if record.truth is None:
                continue
            if current and record.segment != current[-1].segment:
                close()
                current = []
            current.append(record)
        close()
        return summaries

    def save_csv(self, path: Path) -> Path:
        """One row per step (truth, estimate, novelty, reward, latency, psi), as metric tables."""
        from zeus_ros.offline.evaluation.metrics import write_csv

        names = self.context_names
        columns = ['step', 'episode', 'segment', 'first', 'reward',
                   *[f'true_{n}' for n in names], *[f'estimated_{n}' for n in names],
                   'novelty', 'novelty_threshold', 'history_length', 'latency_ms', 'psi']
        rows = []
        for r in self.ordered():
            row = {'step': r.step, 'episode': r.episode, 'segment': r.segment,
                   'first': int(r.first), 'reward': r.reward,
                   'history_length': r.history_length, 'latency_ms': r.latency_ms,
                   'psi': None if r.estimate is None else ' '.join(f'{v:.5g}' for v in r.estimate)}
            row.update(zip((f'true_{n}' for n in names), r.truth or (), strict=False))
            row.update(zip((f'estimated_{n}' for n in names), r.readout or (), strict=False))
            row.update(zip(('novelty', 'novelty_threshold'), r.novelty or (), strict=False))
            rows.append(row)
        return write_csv(path, rows, columns)

    def latencies_ms(self) -> np.ndarray:
        """All measured observation-to-action latencies."""
        values = [r.latency_ms for r in self.records.values() if r.latency_ms is not None]
        return np.asarray(values, dtype=np.float64)


def format_segments(segments: Sequence[SegmentSummary], names: Sequence[str]) -> str:
    """A fixed-width table of the segment summaries."""
    read = any(s.estimated for s in segments)
    scored = any(s.novel is not None for s in segments)
    header = f'{"seg":>4} {"steps":>6} {"from":>6} {"to":>6}  {"context":<28} ' \
             + (f'{"estimated":<14} ' if read else '') \
             + f'{"return":>9} {"per step":>9} {"psi spread":>10}' \
             + (f' {"novel":>6}' if scored else '')
    lines = [header, '-' * len(header)]
    for s in segments:
        context = ', '.join(f'{n}={v:g}' for n, v in zip(names, s.context, strict=False))
        spread = '' if s.context_error is None else f'{s.context_error:10.3f}'
        estimated = ', '.join(f'{v:.3g}' for v in s.estimated or ())
        novel = '' if s.novel is None else f'{s.novel:6.0%}'
        lines.append(f'{s.segment:>4} {s.steps:>6} {s.first_step:>6} {s.last_step:>6}  '
                     f'{context:<28} ' + (f'{estimated:<14} ' if read else '')
                     + f'{s.total_return:>9.2f} {s.reward_per_step:>9.3f} {spread:>10}'
                     + (f' {novel:>6}' if scored else ''))
    return '\n'.join(lines)


def _projection(points: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
    """First two principal components and the share of variance each explains."""
    centered = points - points.mean(0)
    if points.shape[1] < 2 or not np.any(centered):
        return np.zeros((points.shape[0], 2)), (0.0, 0.0)
    _u, s, vt = np.linalg.svd(centered, full_matrices=False)
    share = s ** 2 / max(float((s ** 2).sum()), 1e-12)
    return centered @ vt[:2].T, (float(share[0]), float(share[1]))


def plot_inspection(log: StepLog, path: Path, title: str = '') -> Path:
    """Save the inspection figure: context over time, psi projection, return per segment.

    The estimate drawn in the first panel is the estimator's own read-out (calibrated offline
    and stored in its checkpoint), never a map fitted on the run it is drawn over.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from zeus_ros.labels import context_label

    records = [r for r in log.ordered() if r.truth is not None]
    segments = log.segments()
    name = log.context_names[0] if log.context_names else 'context'
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    ax = axes[0]
    steps = np.array([r.step for r in records])
    truth = np.array([r.truth[0] for r in records]) if records else np.zeros(0)
    ax.plot(steps, truth, color='black', lw=2, label=f'true {name}')
    # An empty history (episode start) gives psi of nothing: one constant point that would
    # dominate the projection, so only estimates from at least one transition are drawn.
    with_est = [r for r in records if r.estimate is not None and r.estimate.size
                and r.history_length > 0]
    read = [r for r in with_est if r.readout]
    if read:
        ax.plot([r.step for r in read], [r.readout[0] for r in read], color='tab:blue', lw=1,
                alpha=0.8, label='estimated (read-out stored in the checkpoint)')
    elif with_est:
        ax.text(0.01, 0.02, 'no read-out in this checkpoint (zeus export calibrates one):\n'
                'psi is shown in the middle panel only', transform=ax.transAxes, fontsize=7,
                va='bottom')
    for s in segments[1:]:
        ax.axvline(s.first_step, color='tab:red', ls='--', lw=0.8)
    ax.set_xlabel('control step')
    ax.set_ylabel(context_label(name))
    ax.set_title('context over time (dashed: switches)', fontsize=10)
    ax.legend(loc='upper left', fontsize=8, framealpha=0.6)

    ax = axes[1]
    if with_est:
        xy, share = _projection(np.stack([r.estimate for r in with_est]))
        colour = [r.truth[0] for r in with_est]
        scatter = ax.scatter(xy[:, 0], xy[:, 1], c=colour, cmap='viridis', s=6)
        fig.colorbar(scatter, ax=ax, label=f'true {context_label(name)}')
        ax.set_xlabel(f'psi PC1 ({share[0]:.0%} of variance)')
        ax.set_ylabel(f'psi PC2 ({share[1]:.0%} of variance)')
    else:
        ax.set_xlabel('psi PC1')
        ax.set_ylabel('psi PC2')
    ax.set_title('psi(H), 2-D PCA, coloured by true context', fontsize=10)

    ax = axes[2]
    if segments:
        labels = [f'{s.segment}: {s.context[0]:g}' if s.context else str(s.segment)
                  for s in segments]
        ax.bar(range(len(segments)), [s.reward_per_step for s in segments], color='tab:green')
        ax.set_xticks(range(len(segments)), labels, rotation=60, fontsize=7)
    ax.set_xlabel(f'segment: {context_label(name)}')
    ax.set_ylabel('reward per step')
    ax.set_title('reward per step, per context segment', fontsize=10)
    if title:
        fig.suptitle(title)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.94 if title else 1.0))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def percentile(values: np.ndarray, q: float) -> float:
    """Percentile that is NaN (not an error) for an empty array."""
    return float(np.percentile(values, q)) if values.size else math.nan
