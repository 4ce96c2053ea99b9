"""Continual deployment after a swap: the live regression check and the recording's retention.

ROS-free arithmetic the live trainer feeds from zeus/step and zeus/context_truth:
- `SegmentReturns` sums the reward of each context segment as it streams by;
- `LiveCheck` compares the return per step the swapped-in checkpoint earns live in the first
  `segments` complete segments after the swap with what the replaced checkpoint earned live in
  segments **of the same context** (paired by the context truth, since its own deployment);
  scaled to an episode, a mean loss beyond the gate's tolerance rolls the swap back. Live is
  compared with live (same schedule, exploration and mid-episode segments): the gate's
  in-process episodes start from resets and read differently, so its gain only sets the
  logged expectation. Segments whose context the replaced checkpoint never met are not judged
  (the check waits for paired ones, at most 3 x `segments`, then compares unpaired);
- `NoveltyAlarm` watches the estimator's novelty flag (zeus/context_novelty): when most of
  the recent steps are outside the checkpoint's training contexts, a round need not wait for
  the full `new_steps` (the contexts it was not trained for are where a round can gain);
- `prune_recording` deletes the oldest closed splits beyond a byte budget, never one still
  needed (those since the last swap) and never the split being written.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
import shutil

__all__ = ['LiveCheck', 'NoveltyAlarm', 'SegmentReturns', 'folder_bytes', 'prune_recording']


@dataclass
class SegmentReturns:
    """Reward and steps of each context segment (segment id -> [reward, steps])."""

    current: int = -1
    totals: dict[int, list[float]] = field(default_factory=dict)
    contexts: dict[int, tuple[float, ...]] = field(default_factory=dict)

    def on_truth(self, segment: int, values: Sequence[float] = ()) -> None:
        """A ContextTruth: the segment (and its context) the next rewards belong to."""
        self.current = int(segment)
        self.contexts.setdefault(self.current, tuple(round(float(v), 4) for v in values))

    def rates(self, first: int, last: int) -> dict[tuple[float, ...], float]:
        """Reward per step per context over the complete segments first..last-1."""
        sums: dict[tuple[float, ...], list[float]] = {}
        for s, (reward, steps) in self.totals.items():
            if first <= s < last and s < self.current and steps:
                total = sums.setdefault(self.contexts.get(s, ()), [0.0, 0])
                total[0] += reward
                total[1] += steps
        return {c: r / n for c, (r, n) in sums.items()}

    def on_step(self, reward: float, first: bool) -> None:
        """A StepFeedback: its reward counts for the current segment (a reset earns none)."""
        if first or self.current < 0:
            return
        total = self.totals.setdefault(self.current, [0.0, 0])
        total[0] += float(reward)
        total[1] += 1

    def complete_after(self, segment: int) -> list[tuple[int, float, int]]:
        """(segment, reward, steps) of the segments after `segment` that have ended."""
        return [(s, t[0], int(t[1])) for s, t in sorted(self.totals.items())
                if segment < s < self.current and t[1] > 0]



@dataclass
class LiveCheck:
    """One swap under watch: the live baseline, the gate's figures, when the watch started."""

    after_segment: int
    """The segment in progress at the swap: it mixes both checkpoints, so it is not judged."""
    since_segment: int
    """The first segment of the replaced checkpoint (its own swap, or the start)."""
    gain: float
    """The gate's paired gain per episode: what the swap should add (logged)."""
    tolerance: float
    tolerance_floor: float
    episode_length: int
    segments: int = 2

    def verdict(self, returns: SegmentReturns) -> tuple[str, float, float] | None:
        """None while watching; ('keep' | 'rollback', live change, allowed loss) per episode."""
        before = returns.rates(self.since_segment, self.after_segment)
        done = returns.complete_after(self.after_segment)
        paired = [(s, r, n) for s, r, n in done if returns.contexts.get(s, ()) in before]
        judged = paired[:self.segments]
        if len(judged) < self.segments and len(done) < 3 * self.segments:
            return None
        if len(judged) < self.segments:  # no context met by both: the mean of all before
            judged = done[:self.segments]
            base = (sum(before.values()) / len(before)) if before else 0.0
            bases = [base] * len(judged)
        else:
            bases = [before[returns.contexts.get(s, ())] for s, _, _ in judged]
        steps = sum(n for _, _, n in judged)
        live = sum(r for _, r, _ in judged) / steps * self.episode_length
        base = sum(b * n for b, (_, _, n) in zip(bases, judged, strict=True)) / steps
        base *= self.episode_length
        allowed = max(self.tolerance_floor, self.tolerance * abs(base))
        change = live - base
        return ('rollback' if change < -allowed else 'keep'), change, allowed


class NoveltyAlarm:
    """Raised while at least `fraction` of the last `window` scored steps were novel.

    `window` 0 turns it off. The estimator scores a step only once its history holds k
    transitions, so episode starts do not dilute the window.
    """

    def __init__(self, window: int, fraction: float) -> None:
        if window < 0 or not 0.0 < fraction <= 1.0:
            raise ValueError(f'novelty window must be >= 0 and fraction in (0, 1], got '
                             f'{window}, {fraction}')
        self.window = window
        self.fraction = fraction
        self.flags: deque[bool] = deque(maxlen=max(window, 1))

    def on_novelty(self, novel: bool) -> None:
        """One scored step's flag."""
        self.flags.append(bool(novel))

    @property
    def novel_share(self) -> float:
        """Share of novel steps in the window (0 before it is full)."""
        if not self.window or len(self.flags) < self.window:
            return 0.0
        return sum(self.flags) / len(self.flags)

    @property
    def raised(self) -> bool:
        """Whether a round may start early."""
        return bool(self.window) and self.novel_share >= self.fraction


def folder_bytes(folder: Path) -> int:
    """Bytes of every file below `folder`."""
    return sum(p.stat().st_size for p in folder.rglob('*') if p.is_file())


def prune_recording(splits: Sequence[Path], keep_bytes: int, protect: Sequence[Path] = ()
                    ) -> list[Path]:
    """Delete the oldest closed `splits` until they fit `keep_bytes`; returns those deleted.

    `splits` are closed (bags.recording.closed_splits: the one being written is never among them);
    `protect` (the splits since the last swap, the next round's new data) are never deleted.
    """
    if keep_bytes <= 0:
        return []
    kept = {Path(p).resolve() for p in protect}
    sizes = [(Path(b), folder_bytes(Path(b))) for b in splits]
    total = sum(size for _, size in sizes)
    removed = []
    for bag, size in sizes:  # oldest first
        if total <= keep_bytes:
            break
        if bag.resolve() in kept:
            continue
        shutil.rmtree(bag, ignore_errors=True)
        total -= size
        removed.append(bag)
    return removed
