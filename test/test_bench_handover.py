"""bench_handover.py: its rings carry every round, members' work adds up, the bound's sums."""

from __future__ import annotations

from pathlib import Path
import sys

import pytest

from ros_harness import fresh_domain_id, require_ros

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'benchmarks'))

from bench_handover import LOOP_HANDOVERS, loop_bound, publish_cost, ring_round


def test_bound_is_the_in_process_period_over_the_period_with_the_handovers() -> None:
    assert loop_bound(1e-3, 0.0) == 1.0
    assert loop_bound(0.6e-3, 0.1e-3) == pytest.approx(0.6 / (0.6 + LOOP_HANDOVERS * 0.1))


@pytest.mark.slow
def test_pipe_ring_members_work_in_turn() -> None:
    work = [0.4e-3, 0.3e-3, 0.3e-3]  # 200 rounds: 0.2 s of CPU, /proc counts 10 ms ticks
    idle = ring_round('pipe', 200, 64, [0.0] * 3)
    busy = ring_round('pipe', 200, 64, work)
    assert 0 < idle.wall < busy.wall
    assert busy.wall >= sum(work)  # the members work one after another, never side by side
    assert busy.cpu >= 0.7 * sum(work)  # their CPU, read from /proc, holds the busy loops


@pytest.mark.ros
@pytest.mark.parametrize('ring', ['rclpy-events+sender', 'one-process-dds', 'one-process-bus'])
def test_ros_rings_carry_every_round(ring: str, monkeypatch: pytest.MonkeyPatch) -> None:
    require_ros()
    monkeypatch.setenv('ROS_DOMAIN_ID', str(fresh_domain_id()))
    work = [0.4e-3, 0.3e-3, 0.3e-3]
    timing = ring_round(ring, 200, 21168, work)
    assert sum(work) <= timing.wall < 0.5  # each round passed every member's work once
    assert timing.cpu >= 0.7 * sum(work)


def test_unknown_ring_is_named() -> None:
    with pytest.raises(ValueError, match=r"unknown ring 'pipe-dream'.*rclpy-events"):
        ring_round('pipe-dream', 10, 0, [0.0] * 3)


@pytest.mark.ros
@pytest.mark.alone  # timing: see the alone marker (pyproject.toml)
def test_publish_cost_waits_for_its_readers(monkeypatch: pytest.MonkeyPatch) -> None:
    require_ros()
    monkeypatch.setenv('ROS_DOMAIN_ID', str(fresh_domain_id()))
    assert 0 < publish_cost(2, 20, 64) < 0.1  # raises if the two readers never matched
