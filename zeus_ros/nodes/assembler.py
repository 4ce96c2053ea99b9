"""Reassemble one control step from messages that arrive on several topics in any order."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
import time
from typing import Any

__all__ = ['StepAssembler', 'StepParts']


@dataclass
class StepParts:
    """The parts of step `step` received so far, keyed by part name (e.g. 'feedback', 'obs')."""

    step: int
    parts: dict[str, Any] = field(default_factory=dict)
    first_seen: float = field(default_factory=time.monotonic)


class StepAssembler:
    """Calls `on_complete(parts)` once every required part of a step has arrived.

    Steps complete in arrival order of their last part; a step still incomplete when a step
    `window` indices newer completes is dropped and counted (the sender skipped or lost it).
    A part arriving for a step that already completed or was dropped is counted as late; an index
    far behind the newest one means the simulator restarted, and the assembler starts over.
    """

    def __init__(self, required: Iterable[str], on_complete: Callable[[StepParts], None],
                 window: int = 8) -> None:
        self.required = frozenset(required)
        self.on_complete = on_complete
        self.window = window
        self._pending: dict[int, StepParts] = {}
        self._newest_done = -1
        self.dropped = 0
        self.late = 0
        self.duplicates = 0

    def add(self, step: int, name: str, value: Any) -> None:
        """Record one part; fire the callback when the step is complete."""
        if name not in self.required:
            raise ValueError(f'unknown part {name!r}; expected one of {sorted(self.required)}')
        if step < self._newest_done - self.window:
            self.reset()  # the step index went far back: the simulator restarted
        if step <= self._newest_done and step not in self._pending:
            self.late += 1
            return
        entry = self._pending.setdefault(step, StepParts(step))
        if name in entry.parts:
            self.duplicates += 1
        entry.parts[name] = value
        if self.required <= entry.parts.keys():
            del self._pending[step]
            self._newest_done = max(self._newest_done, step)
            for stale in [s for s in self._pending if s < step - self.window]:
                del self._pending[stale]
                self.dropped += 1
            self.on_complete(entry)

    def reset(self) -> None:
        """Forget everything (e.g. after the simulator restarted)."""
        self._pending.clear()
        self._newest_done = -1


class StampJoin:
    """Gives images (which carry no step index) the step of the feedback with the same stamp.

    Every message of one step shares header.stamp, so an image is matched to a step through the
    StepFeedback's stamp, whichever of the two arrives first. Unmatched entries are bounded.
    """

    def __init__(self, deliver: Callable[[int, Any], None], capacity: int = 64) -> None:
        self.deliver = deliver
        self.capacity = capacity
        self._step_of: dict[int, int] = {}
        self._waiting: dict[int, Any] = {}

    def feedback(self, stamp_ns: int, step: int) -> None:
        """A step's stamp became known; deliver its image if it came first."""
        if stamp_ns in self._waiting:
            self.deliver(step, self._waiting.pop(stamp_ns))
            return
        self._step_of[stamp_ns] = step
        self._trim(self._step_of)

    def image(self, stamp_ns: int, value: Any) -> None:
        """An image arrived; deliver it now if its step is known, else hold it."""
        step = self._step_of.pop(stamp_ns, None)
        if step is not None:
            self.deliver(step, value)
            return
        self._waiting[stamp_ns] = value
        self._trim(self._waiting)

    def _trim(self, table: dict[int, Any]) -> None:
        while len(table) > self.capacity:
            del table[next(iter(table))]
