"""Continual deployment after a swap: the live regression check and the recording's retention.

ROS-free arithmetic the live trainer feeds from zeus/step and zeus/context_truth:
- `SegmentReturns` sums the reward of each context segment as it streams by;
- `LiveCheck` compares the return the swapped-in checkpoint earns live (per step, scaled to an
  episode, over the first `segments` complete segments after the swap) with what the gate
  measured for the checkpoint it replaced, less the gate's tolerance: below that, the swap made
  the robot worse than before and is rolled back;
- `prune_recording` deletes the oldest closed splits beyond a byte budget, never one still
  needed (those since the last swap) and never the split being written.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
import shutil

__all__ = ['LiveCheck', 'SegmentReturns', 'folder_bytes', 'prune_recording']


@dataclass
class SegmentReturns:
    """Reward and steps of each context segment (segment id -> [reward, steps])."""

    current: int = -1
    totals: dict[int, list[float]] = field(default_factory=dict)

    def on_truth(self, segment: int) -> None:
        """A ContextTruth: the segment the next rewards belong to."""
        self.current = int(segment)

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
    """One swap under watch: the gate's figures and when the watch started."""

    after_segment: int
    """The segment in progress at the swap: it mixes both checkpoints, so it is not judged."""
    expected: float
    """The gate's return per episode for the candidate on the seen contexts."""
    floor: float
    """The deployed checkpoint's gate return less the gate's tolerance: the live minimum."""
    episode_length: int
    segments: int = 2

    def verdict(self, returns: SegmentReturns) -> tuple[str, float] | None:
        """None while watching; ('keep' | 'rollback', live return per episode) at the end."""
        done = returns.complete_after(self.after_segment)[:self.segments]
        if len(done) < self.segments:
            return None
        steps = sum(s for _, _, s in done)
        live = sum(r for _, r, _ in done) / max(steps, 1) * self.episode_length
        return ('rollback' if live < self.floor else 'keep'), live


def folder_bytes(folder: Path) -> int:
    """Bytes of every file below `folder`."""
    return sum(p.stat().st_size for p in folder.rglob('*') if p.is_file())


def prune_recording(splits: Sequence[Path], keep_bytes: int, protect: Sequence[Path] = ()
                    ) -> list[Path]:
    """Delete the oldest closed `splits` until they fit `keep_bytes`; returns those deleted.

    `splits` are closed (continual.closed_splits: the one being written is never among them);
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
