"""What a node's /diagnostics says, by diagnostic_updater's conventions.

Why: a status that said "ok" while the loop ran at 1.3 Hz (50 Hz expected), or that kept a
WARN for the rest of the run after one event, tells an operator nothing. As diagnostic_updater's
FrequencyStatus and TimeStampStatus do, a rate is checked against an expected rate with a
tolerance (no event in a window after the start: ERROR), a latency against WARN and ERROR
thresholds, and counted faults are reported per window (what happened in the last
`WINDOW_S` seconds), so every WARN and ERROR clears once its cause has. A second publisher on
the node's clock (/clock, or where a launch remapped it) is an ERROR naming it.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
import math
import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.publisher import Publisher

__all__ = ['WINDOW_S', 'ClockWatch', 'WindowCounts', 'latency_problems', 'latency_specs',
           'rate_problems']

WINDOW_S = 5.0
"""Seconds over which counted faults raise a WARN (and after which they no longer do)."""


class WindowCounts:
    """Counters per window: what each grew by over the last `window` seconds."""

    def __init__(self, window: float = WINDOW_S) -> None:
        self.window = window
        self._snapshots: deque[tuple[float, dict[str, int]]] = deque()

    def delta(self, counts: Mapping[str, int]) -> dict[str, int]:
        """How much each count grew in the last `window` s (since the first call, if sooner)."""
        now = time.monotonic()
        snapshots = self._snapshots
        snapshots.append((now, dict(counts)))
        while len(snapshots) > 1 and snapshots[1][0] <= now - self.window:
            snapshots.popleft()
        base = snapshots[0][1]
        return {key: int(value) - int(base.get(key, 0)) for key, value in counts.items()}

    def problems(self, grown: Mapping[str, int], keys: Sequence[str]) -> list[str]:
        """WARN lines for the `keys` that `grown` (a delta) says grew, e.g. '3 timeouts in 5 s'."""
        return [f'{grown[key]} {key} in the last {self.window:g} s' for key in keys
                if grown.get(key, 0) > 0]


def rate_problems(rate_hz: float, events: int, expected_hz: float, tolerance: float,
                  started: bool, what: str = 'steps', window: float = WINDOW_S,
                  upper: bool = False) -> tuple[list[str], list[str]]:
    """(WARN, ERROR) lines for a rate checked against `expected_hz` +- `tolerance` (a fraction).

    `events` counted in the last `window` s; none after `started`: ERROR (stalled). Below
    `expected_hz * (1 - tolerance)`: WARN; above `expected_hz * (1 + tolerance)` only with
    `upper` (a realtime loop; a lockstep simulation may run faster than real time).
    """
    if not started:
        return [], []
    if events == 0:
        return [], [f'no {what} in the last {window:g} s (stalled)']
    if expected_hz <= 0:
        return [], []
    low, high = expected_hz * (1 - tolerance), expected_hz * (1 + tolerance)
    if rate_hz < low:
        return [f'{what} at {rate_hz:.1f} Hz, expected >= {low:.1f} Hz ({expected_hz:g} Hz '
                f'- {tolerance:.0%})'], []
    if upper and rate_hz > high:
        return [f'{what} at {rate_hz:.1f} Hz, expected <= {high:.1f} Hz ({expected_hz:g} Hz '
                f'+ {tolerance:.0%})'], []
    return [], []


def latency_problems(p99_ms: float, warn_ms: float, error_ms: float, what: str
                     ) -> tuple[list[str], list[str]]:
    """(WARN, ERROR) lines for a window's p99 latency (nan: nothing measured, no line)."""
    if math.isnan(p99_ms):
        return [], []
    if error_ms > 0 and p99_ms > error_ms:
        return [], [f'{what} p99 {p99_ms:.0f} ms > {error_ms:g} ms']
    if warn_ms > 0 and p99_ms > warn_ms:
        return [f'{what} p99 {p99_ms:.0f} ms > {warn_ms:g} ms'], []
    return [], []


class ClockWatch:
    """ERROR while the node's clock topic has a publisher other than `own` (or more than one).

    Watched by the clock's publisher (sim_bridge) and by every node that runs on it
    (use_sim_time): two simulators on one /clock make every node's time jump between them.
    """

    def __init__(self, node: Node, own: Publisher | None = None) -> None:
        self._node = node
        self._own = own
        self.topic = node.resolve_topic_name('/clock')

    @property
    def watching(self) -> bool:
        """True for the clock's publisher and for nodes on simulation time."""
        if self._own is not None:
            return True
        return bool(self._node.get_parameter('use_sim_time').value)

    def errors(self) -> list[str]:
        """The ERROR line naming the clock's other publishers (empty: none)."""
        if not self.watching:
            return []
        own = None
        if self._own is not None:
            from zeus_ros.nodes.rcl_bindings import publisher_gid

            own = publisher_gid(self._own)
        names = []
        for info in self._node.get_publishers_info_by_topic(self.topic):
            gid = bytes(info.endpoint_gid)[:16]
            if gid != own:
                names.append(f'{info.node_namespace.rstrip("/")}/{info.node_name} '
                             f'(gid {gid.hex()})')
        limit = 0 if own is not None else 1
        if len(names) <= limit:
            return []
        return [f'{len(names) + (own is not None)} publishers on {self.topic}: '
                f'{", ".join(names)}{" besides this node" if own is not None else ""}; '
                'simulation time jumps between them (give each system its own clock: '
                'clock:=namespace, docs/security.md)']


def latency_specs(warn_ms: float, error_ms: float, what: str, zero_warn: str = 'never',
                  zero_error: str = 'never') -> dict[str, Any]:
    """The two latency threshold parameters of a node (params.Spec), live.

    `zero_warn` / `zero_error` say what 0 means (the bridges: a number of control periods).
    """
    from zeus_ros.nodes.params import Spec

    return {
        'latency_warn_ms': Spec(warn_ms, f'/diagnostics: WARN when the {what} p99 of the last '
                                f'second exceeds it (0: {zero_warn})', live=True, low=0.0,
                                safety=True),
        'latency_error_ms': Spec(error_ms, f'/diagnostics: ERROR when the {what} p99 of the '
                                 f'last second exceeds it (0: {zero_error})', live=True,
                                 low=0.0, safety=True),
    }
