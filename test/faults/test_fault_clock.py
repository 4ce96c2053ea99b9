"""Fault matrix, clock row: two simulated systems in one domain, each on its own clock.

The issue's run: `namespace:=r1 use_sim_time:=true` beside a default /r2 stalled /r1 (both
sim_bridges published on the one global /clock, so every node's time jumped between them).
With `zeus launch --clock namespace`, and by default for a namespaced launch on simulation
time (issue 48, item 7), each system's clock is <namespace>/clock: here two
`zeus launch --sim-time` groups in one domain (/r1 as in the issue's run, no --clock; /r2
with --clock namespace) both step, each clock is monotonic and moves with its own steps only,
and no node reports a second publisher on its clock.
"""

from __future__ import annotations

import itertools
from pathlib import Path
import subprocess
import sys
import time
from typing import Any

import pytest

from live_fixtures import TASK, tiny_checkpoint
from ros_harness import (
    REPO,
    driver_node,
    fresh_domain_id,
    ros_environment,
    spin_until,
    stop_launch,
)

pytestmark = [pytest.mark.ros, pytest.mark.faults_only]


def test_two_namespaced_sim_time_systems_each_keep_their_own_clock(tmp_path: Path) -> None:
    """/r1 (`zeus launch --sim-time`, the default clock) and /r2 (`--clock namespace`)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rosgraph_msgs.msg import Clock
    from zeus_msgs.msg import StepFeedback

    from zeus_ros.nodes.messages import seconds_from_stamp
    from zeus_ros.nodes.topics import step_qos

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    params = tmp_path / 'params.yaml'
    out = tmp_path / 'bag'
    params.write_text(f'/**/sim_bridge:\n  ros__parameters:\n    task: {TASK}\n' + ''.join(
        f'/**/{name}:\n  ros__parameters:\n    checkpoint: {checkpoint}\n    task: {TASK}\n'
        for name in ('context_estimator', 'policy'))
        + f'/**/recorder:\n  ros__parameters:\n    output: {out}\n')
    domain = fresh_domain_id()
    # /r1 as in the run: one process for the loop, recording; /r2 as processes.
    # /r1 forgets --clock, as the run did: the default is its own clock now.
    flags = {'r1': ['--single-process', '--record'], 'r2': ['--clock', 'namespace']}
    launches = {ns: subprocess.Popen(
        [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params', str(params),
         '--namespace', ns, '--sim-time', '--no-progress',
         '--domain-id', str(domain), *flags[ns]],
        cwd=REPO, env=ros_environment(domain), stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL, start_new_session=True) for ns in ('r1', 'r2')}
    clocks: dict[str, list[float]] = {'r1': [], 'r2': [], '': []}
    steps: dict[str, list[float]] = {'r1': [], 'r2': []}
    diagnostics: list[Any] = []
    try:
        with driver_node(domain) as probe:
            for ns in ('r1', 'r2'):
                probe.create_subscription(Clock, f'/{ns}/clock', lambda m, ns=ns: clocks[
                    ns].append(seconds_from_stamp(m.clock)), step_qos(1000))
                probe.create_subscription(StepFeedback, f'/{ns}/zeus/step', lambda m, ns=ns:
                                          steps[ns].append(seconds_from_stamp(m.header.stamp)),
                                          step_qos(1000))
            probe.create_subscription(Clock, '/clock', lambda m: clocks[''].append(1.0),
                                      step_qos(100))
            probe.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 100)
            assert spin_until(probe, lambda: min(map(len, steps.values())) > 300, 180), \
                {ns: len(s) for ns, s in steps.items()}
            started = time.monotonic()
            spin_until(probe, lambda: False, 1.5)  # a /diagnostics round with both stepping
            both = time.monotonic() - started
    finally:
        for launch in launches.values():
            stop_launch(launch)
    for ns in ('r1', 'r2'):
        ticks = clocks[ns]
        assert len(ticks) > 300 and all(b > a for a, b in itertools.pairwise(ticks)), \
            f'/{ns}/clock is not its own monotonic clock'
        assert set(steps[ns]) <= set(ticks), f'/{ns} steps are not stamped with its clock'
    assert not clocks[''], 'something still publishes on the global /clock'
    clash = [s.message for array in diagnostics for s in array.status
             if s.level == DiagnosticStatus.ERROR and 'clock' in s.message]
    assert not clash, clash
    bagged = _bag_clock_and_steps(out)
    assert len(bagged['/clock']) == len(bagged['/zeus/step']) > 300, \
        {topic: len(v) for topic, v in bagged.items()}
    assert bagged['/clock'] == sorted(bagged['/clock']) == bagged['/zeus/step'], \
        "/r1's bag holds another clock than its own steps'"
    print(f'two systems: {len(steps["r1"])} and {len(steps["r2"])} steps, clocks '
          f'{clocks["r1"][-1]:.1f} s and {clocks["r2"][-1]:.1f} s of simulation time '
          f'({both:.1f} s watched together); /r1 bag: {len(bagged["/clock"])} clock messages '
          f'for {len(bagged["/zeus/step"])} steps, in order')


def _bag_clock_and_steps(out: Path) -> dict[str, list[int]]:
    """Nanosecond stamps of /clock and /zeus/step in the bag(s) under `out`."""
    from rosbags.highlevel import AnyReader

    found: dict[str, list[int]] = {'/clock': [], '/zeus/step': []}
    bags = sorted(path.parent for path in out.rglob('metadata.yaml'))
    assert bags, f'no bag under {out}'
    with AnyReader(bags) as reader:
        for connection, _t, raw in reader.messages():
            if connection.topic in found:
                msg = reader.deserialize(raw, connection.msgtype)
                stamp = msg.clock if connection.topic == '/clock' else msg.header.stamp
                found[connection.topic].append(stamp.sec * 10**9 + stamp.nanosec)
    return found
