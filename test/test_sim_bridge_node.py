"""The real sim_bridge node as a subprocess, driven in lockstep from a test node."""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path

import pytest

from ros_harness import ProcessGroup, driver_node, python_module, spin_until

pytestmark = pytest.mark.ros

SWITCH_EVERY = 60
VALUES = [0.6, 1.0, 1.4]
STEPS = 230


@dataclass
class Seen:
    """What the driver received, per topic: step index -> message."""

    state: dict[int, object] = field(default_factory=dict)
    feedback: dict[int, object] = field(default_factory=dict)
    truth: dict[int, object] = field(default_factory=dict)
    clock: list[object] = field(default_factory=list)
    diagnostics: list[object] = field(default_factory=list)


def start_bridge(group: ProcessGroup, *extra: str) -> object:
    """Start sim_bridge on Cheetah-Run-v0 with a switching torso-length schedule."""
    values = '[' + ','.join(str(v) for v in VALUES) + ']'
    return group.start('sim_bridge', python_module(
        'zeus_ros.nodes.sim_bridge_node', '--ros-args',
        '-p', 'task:=Cheetah-Run-v0', '-p', f'max_steps:={STEPS}', '-p', 'seed:=3',
        '-p', 'schedule.kind:=switch', '-p', f'schedule.every:={SWITCH_EVERY}',
        '-p', f'schedule.values:={values}', '-p', 'action_timeout:=0.5', *extra))


def drive(group: ProcessGroup, answer: object) -> Seen:
    """Answer every observation with `answer(step, low, high)` until the node stops."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock
    from zeus_msgs.msg import Action, ContextTruth, StateVector, StepFeedback

    from zeus_ros.nodes.topics import TOPICS, step_qos

    seen = Seen()
    process = start_bridge(group)
    with driver_node(group.domain_id) as node:
        publisher = node.create_publisher(Action, TOPICS.ACTION, step_qos())

        def on_state(msg: StateVector) -> None:
            seen.state[msg.step] = msg
            data = answer(msg.step)
            if data is not None:
                publisher.publish(Action(header=msg.header, step=msg.step, data=data))

        node.create_subscription(StateVector, TOPICS.STATE, on_state, step_qos())
        node.create_subscription(StepFeedback, TOPICS.STEP,
                                 lambda m: seen.feedback.__setitem__(m.step, m), step_qos())
        node.create_subscription(ContextTruth, TOPICS.CONTEXT_TRUTH,
                                 lambda m: seen.truth.__setitem__(m.step, m), step_qos())
        node.create_subscription(Clock, TOPICS.CLOCK, seen.clock.append, step_qos())
        node.create_subscription(DiagnosticArray, TOPICS.DIAGNOSTICS, seen.diagnostics.append,
                                 10)
        finished = spin_until(node, lambda: process.poll() is not None, timeout=120)
    assert finished, 'sim_bridge did not finish:\n' + group.log_text('sim_bridge')[-3000:]
    assert process.returncode == 0, group.log_text('sim_bridge')[-3000:]
    return seen


def zero_action(step: int) -> list[float]:
    """A valid action for every step."""
    return [0.0] * 6


def faulty_action(step: int) -> list[float] | None:
    """Valid actions, except a NaN, a wrong length, an out-of-range value and a silence."""
    if step == 50:
        return [math.nan] + [0.0] * 5
    if step == 80:
        return [0.0] * 4
    if step == 90:
        return [5.0] + [0.0] * 5
    if step == 120:
        return None
    return [0.0] * 6


def test_every_step_arrives_with_matching_step_and_stamp(ros_processes: ProcessGroup) -> None:
    """State, feedback, truth and clock of every step share its index and stamp."""
    seen = drive(ros_processes, zero_action)
    assert sorted(seen.state) == list(range(STEPS + 1))
    assert sorted(seen.feedback) == sorted(seen.state) == sorted(seen.truth)
    clock_stamps = {(c.clock.sec, c.clock.nanosec) for c in seen.clock}
    previous = -1.0
    for step, state in seen.state.items():
        stamp = (state.header.stamp.sec, state.header.stamp.nanosec)
        assert stamp == (seen.feedback[step].header.stamp.sec,
                         seen.feedback[step].header.stamp.nanosec)
        assert stamp == (seen.truth[step].header.stamp.sec, seen.truth[step].header.stamp.nanosec)
        assert stamp in clock_stamps
        seconds = stamp[0] + stamp[1] * 1e-9
        assert seconds > previous, f'stamps must increase (step {step})'
        previous = seconds
    assert all(seen.feedback[k].action_status == 1 for k in range(1, STEPS + 1)
               if not seen.feedback[k].first)


def test_true_context_follows_the_schedule_across_a_mid_episode_switch(
        ros_processes: ProcessGroup) -> None:
    """The truth topic equals the schedule's value for each step, switching mid-episode."""
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config

    seen = drive(ros_processes, zero_action)
    task = make_task('Cheetah-Run-v0')
    schedule = schedule_from_config(
        {'kind': 'switch', 'every': SWITCH_EVERY, 'values': VALUES}, task, 3)
    for step, truth in seen.truth.items():
        expected = schedule.value_at(step, seen.feedback[step].episode)
        assert list(truth.names) == ['torso_length']
        assert truth.values[0] == pytest.approx(expected['torso_length'])
    switches = [k for k in range(1, STEPS + 1)
                if seen.truth[k].values[0] != seen.truth[k - 1].values[0]]
    assert switches, 'the schedule never switched'
    assert any(not seen.feedback[k].first for k in switches), 'no switch happened mid-episode'
    assert seen.truth[switches[0]].segment == seen.truth[switches[0] - 1].segment + 1


def test_bad_actions_are_counted_and_the_node_keeps_running(
        ros_processes: ProcessGroup) -> None:
    """NaN and wrong-length actions are rejected, out-of-range clipped, silence times out."""
    seen = drive(ros_processes, faulty_action)
    assert sorted(seen.state) == list(range(STEPS + 1)), 'the node stopped early'
    status = {k: seen.feedback[k].action_status for k in (51, 81, 91, 121)}
    assert status == {51: 3, 81: 3, 91: 2, 121: 4}
    assert max(seen.feedback[91].applied_action) == pytest.approx(1.0)
    assert list(seen.feedback[51].applied_action) == [0.0] * 6
    log = ros_processes.log_text('sim_bridge')
    assert "'rejected': 2" in log and "'timeouts': 1" in log and "'clipped': 1" in log, log
    assert 'nan' in log.lower()
    assert seen.diagnostics, 'no /diagnostics from sim_bridge'
    # The loop's own latency (StepFeedback k out -> Action k in), over the answered steps only:
    # the silent step 120 has none.
    from zeus_ros.nodes.meters import SUMMARY

    found = SUMMARY.search(log)
    assert found, log[-3000:]
    p50, p99, answered = float(found[1]), float(found[2]), int(found[3])
    assert 0 < p50 <= p99 < 500 and answered == STEPS, found[0]


def test_bad_parameter_fails_at_start_with_a_clear_message(ros_processes: ProcessGroup) -> None:
    """An unknown task name stops the node with exit code 2 naming parameter and choices."""
    process = start_bridge(ros_processes, '-p', 'task:=Cheetah-Fly-v9')
    assert process.wait(timeout=60) == 2
    log = ros_processes.log_text('sim_bridge')
    assert 'task' in log and 'Cheetah-Fly-v9' in log and 'Walker-Walk-v0' in log


def test_realtime_mode_keeps_stepping_and_marks_stale_actions(
        ros_processes: ProcessGroup) -> None:
    """Realtime: the clock drives the steps; once actions stop, the safe action is STALE."""
    from zeus_msgs.msg import Action, StateVector, StepFeedback

    from zeus_ros.nodes.topics import TOPICS, action_qos, step_qos

    process = ros_processes.start('sim_bridge', python_module(
        'zeus_ros.nodes.sim_bridge_node', '--ros-args', '-p', 'task:=Cheetah-Run-v0',
        '-p', 'mode:=realtime', '-p', 'control_rate:=50.0', '-p', 'max_steps:=80'))
    feedback: dict[int, object] = {}
    with driver_node(ros_processes.domain_id) as node:
        publisher = node.create_publisher(Action, TOPICS.ACTION, action_qos('realtime'))

        def on_state(msg: StateVector) -> None:
            if msg.step < 30:
                publisher.publish(Action(header=msg.header, step=msg.step, data=[0.1] * 6))

        node.create_subscription(StateVector, TOPICS.STATE, on_state, step_qos())
        node.create_subscription(StepFeedback, TOPICS.STEP,
                                 lambda m: feedback.__setitem__(m.step, m), step_qos())
        assert spin_until(node, lambda: process.poll() is not None, timeout=60), \
            ros_processes.log_text('sim_bridge')[-2000:]
    assert max(feedback) >= 79, 'realtime stepping stopped without actions'
    answered = [feedback[k].action_status for k in range(5, 25) if k in feedback]
    assert answered.count(1) >= len(answered) // 2, answered
    late = [feedback[k].action_status for k in range(45, 80) if k in feedback]
    assert late and set(late) == {5}, late


@pytest.mark.parametrize(('content', 'expected'), [
    ('garbage: [unclosed\n', 'line 2: not valid YAML'),
    ('policy:\n  checkpoint: x.pt\n', "node 'policy' needs a ros__parameters: mapping"),
    (None, 'cannot read it (No such file or directory)'),
])
def test_a_bad_params_file_is_one_line_before_rclpy_starts(
        tmp_path: Path, content: str | None, expected: str) -> None:
    """A node given a broken params file names the file and the fault, exit 2, no traceback."""
    import subprocess

    from ros_harness import fresh_domain_id, ros_environment

    path = tmp_path / 'params.yaml'
    if content is not None:
        path.write_text(content)
    for module in ('zeus_ros.nodes.sim_bridge_node', 'zeus_ros.nodes.policy_node'):
        done = subprocess.run(python_module(module, '--ros-args', '--params-file', str(path)),
                              env=ros_environment(fresh_domain_id()), capture_output=True,
                              text=True, timeout=60, check=False)
        assert done.returncode == 2, done.stderr
        line = done.stderr.strip()
        assert line.startswith(f'error: --params-file {path}') and expected in line, line
        assert len(line.splitlines()) == 1, line
        assert 'Traceback' not in done.stderr
