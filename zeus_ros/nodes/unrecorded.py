"""What a recorder that cannot write owes its operator: which steps no bag holds, when to retry.

Kept apart from the node so the bookkeeping (ranges, back-off) is plain, testable Python.
"""

from __future__ import annotations

__all__ = ['Unrecorded', 'ranges_text']


def ranges_text(ranges: list[list[int]], limit: int = 6) -> str:
    """'120-437, 500' for [[120, 437], [500, 500]]; the oldest beyond `limit` are summed up."""
    parts = [f'{a}-{b}' if b > a else f'{a}' for a, b in ranges]
    if len(parts) > limit:
        parts = [f'{len(parts) - limit} earlier range(s)', *parts[-limit:]]
    return ', '.join(parts)


class Unrecorded:
    """Step ranges that no bag holds and the back-off of a recorder that cannot write.

    `fail` starts a failure (a range opens at the first step not safely in a bag), `note`
    stretches the open range over every step heard meanwhile, `retry_due` / `retry_failed`
    pace the tries of a new bag (doubling `first_s` up to `max_s`), `recovered` closes it.
    """

    def __init__(self, first_s: float, max_s: float) -> None:
        self.first_s = first_s
        self.max_s = max_s
        self.ranges: list[list[int]] = []
        self.error = ''
        """Why the recorder cannot write now ('' while it writes)."""
        self.failures = 0
        """Write failures so far (each one a dropped bag or a refused new one)."""
        self.wait_s = first_s
        self.retry_at = 0.0
        self._open = False

    @property
    def failing(self) -> bool:
        """True from a write failure until a new bag is open."""
        return bool(self.error)

    @property
    def steps(self) -> int:
        """How many steps no bag holds."""
        return sum(b - a + 1 for a, b in self.ranges)

    def fail(self, error: str, now: float, first: int | None, last: int | None) -> None:
        """A write failed: steps from `first` (the first not flushed) to `last` are lost."""
        self.error = error
        self.failures += 1
        self.wait_s = self.first_s
        self.retry_at = now + self.wait_s
        self._open = False
        if first is not None and last is not None and last >= first:
            self._add(first, last)

    def note(self, step: int) -> None:
        """A step was heard while failing: it is in no bag."""
        if self._open and self.ranges[-1][0] <= step:
            self.ranges[-1][1] = max(self.ranges[-1][1], step)
        else:
            self._add(step, step)

    def _add(self, first: int, last: int) -> None:
        if self.ranges and self.ranges[-1][0] <= first <= self.ranges[-1][1] + 1:
            self.ranges[-1][1] = max(self.ranges[-1][1], last)  # adjacent: one range
        else:
            self.ranges.append([first, last])
        self._open = True

    def retry_due(self, now: float) -> bool:
        """Time for the next try of a new bag."""
        return self.failing and now >= self.retry_at

    def retry_failed(self, error: str, now: float) -> None:
        """The new bag failed too: wait twice as long (at most `max_s`)."""
        self.error = error
        self.failures += 1
        self.wait_s = min(self.max_s, self.wait_s * 2)
        self.retry_at = now + self.wait_s

    def recovered(self) -> str:
        """A new bag is open: close the failure; returns the ranges lost so far, as text."""
        self.error = ''
        self._open = False
        self.wait_s = self.first_s
        return ranges_text(self.ranges)

    def summary(self) -> str:
        """'N steps (ranges)' or '' when every step was written."""
        return f'{self.steps} steps ({ranges_text(self.ranges)})' if self.ranges else ''
