"""The nodes' own meters for /diagnostics: the event rate and latency percentiles."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from zeus_ros.nodes.meters import LatencyMeter, RateMeter


def test_latency_percentiles_are_within_one_percent_of_the_samples() -> None:
    """Log-binned percentiles agree with numpy's on the same samples (2 % bins)."""
    rng = np.random.default_rng(0)
    samples = rng.lognormal(mean=math.log(1e-3), sigma=0.8, size=20_000)  # ~1 ms, long tail
    meter = LatencyMeter()
    for value in samples:
        meter.add(float(value))
    assert meter.count == samples.size
    for got, q in zip(meter.percentiles_ms((50, 90, 99)), (50, 90, 99), strict=True):
        assert got == pytest.approx(np.percentile(samples, q) * 1e3, rel=0.015)


def test_report_covers_what_came_since_the_last_report() -> None:
    """Each report sees only its window; the run's percentiles keep everything."""
    meter = LatencyMeter()
    assert all(math.isnan(v) for v in meter.percentiles_ms())
    (p50, p99), count = meter.report()
    assert count == 0 and math.isnan(p50) and math.isnan(p99)
    for _ in range(100):
        meter.add(0.001)
    (p50, _), count = meter.report()
    assert count == 100 and p50 == pytest.approx(1.0, rel=0.01)
    for _ in range(300):
        meter.add(0.010)
    (p50, p99), count = meter.report()
    assert count == 300 and p50 == pytest.approx(10.0, rel=0.01)
    assert meter.percentiles_ms((10, 90)) == pytest.approx([1.0, 10.0], rel=0.01)


def test_latency_outside_the_range_is_clamped_not_lost() -> None:
    """Zero, negative (clock steps) and huge latencies land in the end bins."""
    meter = LatencyMeter()
    for value in (0.0, -1.0, 1e9):
        meter.add(value)
    low, high = meter.percentiles_ms((1, 100))
    assert meter.count == 3
    assert low == pytest.approx(LatencyMeter.FLOOR_S * 1e3, rel=0.02)
    assert high == pytest.approx(LatencyMeter.CEILING_S * 1e3, rel=0.02)


def test_rate_counts_events_in_its_window_only() -> None:
    """A rate over the window: old events fall out, fewer than two give 0."""
    meter = RateMeter(window=0.2)
    assert meter.rate == 0.0
    for _ in range(11):
        meter.tick()
        time.sleep(0.01)
    assert 50 < meter.rate < 110  # ~100 events/s, sleep granularity aside
    time.sleep(0.3)
    meter.tick()
    assert meter.rate == 0.0  # the earlier events left the window
