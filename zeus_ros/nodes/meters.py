"""What the nodes measure about their own loop for /diagnostics: rates and latencies.

ROS-free on purpose: a node feeds these on its hot path (one call per step), so each call is
a few hundred nanoseconds of plain Python, and the /diagnostics timer reads them once a second.
"""

from __future__ import annotations

from collections import deque
import math
import re
import time

import numpy as np

__all__ = ['SUMMARY', 'LatencyMeter', 'RateMeter']


class RateMeter:
    """Events per second over a sliding window of wall-clock time (for /diagnostics)."""

    def __init__(self, window: float = 5.0) -> None:
        self._window = window
        self._times: deque[float] = deque()

    def tick(self) -> None:
        """Record one event now."""
        now = time.monotonic()
        times = self._times
        times.append(now)
        cutoff = now - self._window
        while times[0] < cutoff:
            times.popleft()

    @property
    def rate(self) -> float:
        """Events per second in the window (0 with fewer than two events)."""
        if len(self._times) < 2:
            return 0.0
        span = self._times[-1] - self._times[0]
        return (len(self._times) - 1) / span if span > 0 else 0.0


SUMMARY = re.compile(r'observation -> action p50 ([\d.]+|nan) ms p99 ([\d.]+|nan) ms over '
                     r'(\d+) answered steps')
"""`LatencyMeter.summary()`'s line as a log reader finds it: p50, p99 (ms) and the count."""


class LatencyMeter:
    """Latency percentiles since the start and since the last report, from log-spaced bins.

    Why bins and not samples: a loop at 1 kHz for a day would keep ~10^8 samples; bins 2 %
    wide from 1 us to 100 s hold any run in a fixed ~930 counts, and a percentile read from
    them is within 1 % of the sample's (the middle of its bin, on a log scale).
    """

    FLOOR_S = 1e-6
    CEILING_S = 100.0
    WIDTH = 1.02

    def __init__(self) -> None:
        self._scale = 1.0 / math.log(self.WIDTH)
        self._bins = math.ceil(math.log(self.CEILING_S / self.FLOOR_S) * self._scale)
        self._counts = [0] * self._bins
        self._reported = np.zeros(self._bins, np.int64)  # the counts at the last report()

    def add(self, seconds: float) -> None:
        """Count one latency (clamped to [FLOOR_S, CEILING_S])."""
        ratio = seconds / self.FLOOR_S
        index = int(math.log(ratio) * self._scale) if ratio > 1.0 else 0
        self._counts[min(index, self._bins - 1)] += 1

    @property
    def count(self) -> int:
        """Latencies counted since the start."""
        return sum(self._counts)

    def percentiles_ms(self, qs: tuple[float, ...] = (50, 99)) -> list[float]:
        """Percentiles (0-100) in ms since the start (nan before the first latency)."""
        return self._percentiles(np.asarray(self._counts, np.int64), qs)

    def report(self, qs: tuple[float, ...] = (50, 99)) -> tuple[list[float], int]:
        """Percentiles in ms and the count since the last report (nan where none); marks now."""
        counts = np.asarray(self._counts, np.int64)
        window = counts - self._reported
        self._reported = counts
        return self._percentiles(window, qs), int(window.sum())

    def diagnostics_values(self) -> dict[str, str]:
        """/diagnostics values: p50 / p99 ms of the last report's window and of the run."""
        (p50, p99), samples = self.report()
        run_p50, run_p99 = self.percentiles_ms()
        return {'latency_p50_ms': f'{p50:.2f}', 'latency_p99_ms': f'{p99:.2f}',
                'latency_p50_ms_run': f'{run_p50:.2f}', 'latency_p99_ms_run': f'{run_p99:.2f}',
                'latency_samples': str(samples)}

    def summary(self) -> str:
        """One line for a node's closing log: the run's p50 / p99 and how many (SUMMARY)."""
        p50, p99 = self.percentiles_ms()
        return (f'observation -> action p50 {p50:.2f} ms p99 {p99:.2f} ms over {self.count} '
                'answered steps')

    def _percentiles(self, counts: np.ndarray, qs: tuple[float, ...]) -> list[float]:
        total = int(counts.sum())
        if total == 0:
            return [math.nan] * len(qs)
        cumulative = np.cumsum(counts)
        out = []
        for q in qs:
            index = int(np.searchsorted(cumulative, max(q / 100 * total, 1), side='left'))
            out.append(self.FLOOR_S * self.WIDTH ** (index + 0.5) * 1e3)
        return out
