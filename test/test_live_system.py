"""The three deployment nodes (plus the recorder) as real processes on one domain."""

from __future__ import annotations

import signal
import time

import numpy as np
import pytest

from live_fixtures import (
    TASK,
    assert_ingests_as_one_by_one,
    check_lockstep_bag,
    container,
    node,
    start_gates,
    tiny_checkpoint,
)
from ros_harness import ProcessGroup, driver_node, spin_until

pytestmark = pytest.mark.ros
STEPS = 320


def bridge_params(steps: int, *extra: str) -> tuple[str, ...]:
    """sim_bridge's parameters: the task with a mid-episode switching schedule."""
    return (f'task:={TASK}', f'max_steps:={steps}', 'schedule.kind:=switch',
            'schedule.every:=100', 'schedule.values:=[0.6,1.0,1.4]', *extra)


def bridge(steps: int, *extra: str) -> list[str]:
    """sim_bridge on the task with a mid-episode switching schedule, as its own process."""
    return node('sim_bridge', *bridge_params(steps, *extra))


def test_three_nodes_act_on_every_step_and_the_bag_trains(
        ros_processes: ProcessGroup, tmp_path) -> None:
    """300+ lockstep steps: an action per step, stamps match, the recorded bag trains.

    The nodes get the start-up parameters a launcher gives them (start_gates): the bag then
    holds every topic from step 0 however late a reader's side of a match comes.
    """
    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    bag_dir = tmp_path / 'bag'
    recorder = ros_processes.start('recorder', node('recorder', f'output:={bag_dir}',
                                                    *start_gates('recorder')))
    ros_processes.start('estimator', node('context_estimator', f'checkpoint:={checkpoint}',
                                          *start_gates('context_estimator')))
    ros_processes.start('policy', node('policy', f'checkpoint:={checkpoint}',
                                       *start_gates('policy')))
    ros_processes.wait_for_log('recorder', 'recording ')
    sim = ros_processes.start('sim_bridge', bridge(STEPS, *start_gates('sim_bridge')))
    assert sim.wait(timeout=180) == 0, ros_processes.log_text('sim_bridge')[-3000:]
    time.sleep(1.5)
    assert ros_processes.stop(recorder, signal.SIGINT) == 0, ros_processes.log_text('recorder')
    check_lockstep_bag(bag_dir, checkpoint, STEPS)


@pytest.mark.parametrize('switch', [(), ('--no-intra-process',)], ids=['intra', 'dds'])
def test_one_process_acts_on_every_step_and_the_bag_trains(
        ros_processes: ProcessGroup, tmp_path, switch: tuple[str, ...]) -> None:
    """The same loop as nodes of one process on one executor (zeus launch --single-process).

    With intra-process delivery (the default) the nodes hand each other the messages in
    process; the recorder outside still gets every one, and no node gets one twice (a second
    action for a step would be counted as unexpected by sim_bridge).
    """
    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    bag_dir = tmp_path / 'bag'
    recorder = ros_processes.start('recorder', node('recorder', f'output:={bag_dir}',
                                                    *start_gates('recorder')))
    ros_processes.wait_for_log('recorder', 'recording ')
    loop = ros_processes.start('container', container({
        'sim_bridge': bridge_params(STEPS, *start_gates('sim_bridge')),
        'context_estimator': (f'checkpoint:={checkpoint}', *start_gates('context_estimator')),
        'policy': (f'checkpoint:={checkpoint}', *start_gates('policy'))}, *switch))
    assert loop.wait(timeout=180) == 0, ros_processes.log_text('container')[-3000:]
    time.sleep(1.5)
    assert ros_processes.stop(recorder, signal.SIGINT) == 0, ros_processes.log_text('recorder')
    check_lockstep_bag(bag_dir, checkpoint, STEPS)
    log = ros_processes.log_text('container')
    assert "'unexpected': 0" in log and 'gap before step' not in log, log[-3000:]


def diagnostics_value(messages: list, node_name: str, key: str) -> int:
    """Newest integer value of `key` that `node_name` reported on /diagnostics (0 if none)."""
    for array in reversed(messages):
        for status in array.status:
            if status.name.lstrip('/').startswith(node_name):
                values = {kv.key: kv.value for kv in status.values}
                if key in values:
                    return int(values[key])
    return 0


def test_policy_survives_estimator_loss_and_resumes(
        ros_processes: ProcessGroup, tmp_path) -> None:
    """Killing the estimator gives stale then safe actions; a restart brings estimates back."""
    from diagnostic_msgs.msg import DiagnosticArray
    from zeus_msgs.msg import Action, ContextEstimate

    from zeus_ros.nodes.topics import TOPICS, step_qos

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    estimator_argv = node('context_estimator', f'checkpoint:={checkpoint}')
    estimator = ros_processes.start('estimator', estimator_argv)
    ros_processes.start('policy', node('policy', f'checkpoint:={checkpoint}',
                                       'context_deadline:=0.05', 'context_timeout:=1.0'))
    ros_processes.start('sim_bridge', bridge(0, 'action_timeout:=5.0', 'min_observers:=2'))
    actions: list[int] = []
    estimates: list[int] = []
    diagnostics: list = []
    with driver_node(ros_processes.domain_id) as probe:
        probe.create_subscription(Action, TOPICS.ACTION, lambda m: actions.append(m.step),
                                  step_qos())
        probe.create_subscription(ContextEstimate, TOPICS.CONTEXT,
                                  lambda m: estimates.append(m.step), step_qos())
        probe.create_subscription(DiagnosticArray, TOPICS.DIAGNOSTICS, diagnostics.append, 50)
        assert spin_until(probe, lambda: len(estimates) > 100, timeout=90), \
            ros_processes.log_text('policy')[-2000:]
        ros_processes.stop(estimator, signal.SIGKILL)
        killed_at = actions[-1]
        assert spin_until(probe, lambda: actions[-1] > killed_at + 40, timeout=60), \
            'the policy stopped acting without its estimator'
        assert spin_until(probe, lambda: diagnostics_value(diagnostics, 'policy', 'safe') > 0,
                          timeout=30), 'no safe actions reported after the context timeout'
        assert diagnostics_value(diagnostics, 'policy', 'stale') > 0
        before_restart = len(estimates)
        ros_processes.start('estimator2', estimator_argv)
        assert spin_until(probe, lambda: len(estimates) > before_restart + 50, timeout=90), \
            'estimates did not resume after the restart'
        # A NaN action from elsewhere is rejected or dropped by sim_bridge; nothing stops.
        publisher = probe.create_publisher(Action, TOPICS.ACTION, step_qos())
        publisher.publish(Action(step=actions[-1] + 1, data=[float('nan')] * 6))
        last = actions[-1]
        assert spin_until(probe, lambda: actions[-1] > last + 30, timeout=60)
    assert all(p.poll() is None for name, p in ros_processes.processes if name != 'estimator')


def test_estimator_rejects_a_malformed_frame_and_keeps_going(
        ros_processes: ProcessGroup, tmp_path) -> None:
    """A frame of the wrong size is counted as rejected; the next good frame gets an estimate."""
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import Image
    from zeus_msgs.msg import ContextEstimate, StepFeedback

    from zeus_ros.nodes.messages import image_from_array
    from zeus_ros.nodes.topics import TOPICS, step_qos

    checkpoint = tiny_checkpoint(tmp_path / 'pixels.pt', obs_kind='pixels')
    ros_processes.start('estimator', node('context_estimator', f'checkpoint:={checkpoint}'))
    estimates: list[int] = []
    diagnostics: list = []
    with driver_node(ros_processes.domain_id) as probe:
        pub_step = probe.create_publisher(StepFeedback, TOPICS.STEP, step_qos())
        pub_image = probe.create_publisher(Image, TOPICS.IMAGE, step_qos())
        probe.create_subscription(ContextEstimate, TOPICS.CONTEXT,
                                  lambda m: estimates.append(m.step), step_qos())
        probe.create_subscription(DiagnosticArray, TOPICS.DIAGNOSTICS, diagnostics.append, 50)
        assert spin_until(probe, lambda: probe.count_subscribers(TOPICS.IMAGE) > 0, timeout=60)
        time.sleep(0.5)
        for step, size in ((0, 84), (1, 64), (2, 84)):
            feedback = StepFeedback(step=step, first=step == 0, applied_action=[] if step == 0
                                    else [0.0] * 6, action_status=0 if step == 0 else 1)
            feedback.header.stamp.nanosec = 1000 + step
            frame = np.full((size, size, 3), 40 * step, np.uint8)
            pub_step.publish(feedback)
            pub_image.publish(image_from_array(frame, feedback.header.stamp))
        assert spin_until(probe, lambda: 2 in estimates, timeout=30)
        assert spin_until(
            probe, lambda: diagnostics_value(diagnostics, 'context_estimator', 'rejected') == 1,
            timeout=10)
    assert 1 not in estimates


@pytest.mark.parametrize('lag', [0, 1], ids=['lag0', 'lag1'])
def test_live_recording_and_zeus_collect_ingest_to_identical_arrays(
        ros_processes: ProcessGroup, tmp_path, monkeypatch, lag: int) -> None:
    """The same checkpoint, seed and schedule live (4 processes) and in-process: same arrays.

    The recorded bag also ingests in batches exactly as decoded one message at a time. With
    the policy's context_lag 1 (acting on context k - 1, the estimator off the critical path)
    the live actions equal `zeus collect --context-lag 1`'s.
    """
    from zeus_ros.cli import collect
    from zeus_ros.offline.data.ingest import ingest_bags

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    bag_dir = tmp_path / 'live'
    recorder = ros_processes.start('recorder', node('recorder', f'output:={bag_dir}',
                                                    *start_gates('recorder')))
    ros_processes.start('estimator', node('context_estimator', f'checkpoint:={checkpoint}',
                                          *start_gates('context_estimator')))
    # A generous context deadline: under CPU load a late context must be waited for, not
    # replaced by the newest one, or the two runs would (legitimately) act differently.
    ros_processes.start('policy', node('policy', f'checkpoint:={checkpoint}',
                                       'context_deadline:=10.0', f'context_lag:={lag}',
                                       *start_gates('policy')))
    ros_processes.wait_for_log('recorder', 'recording ')
    sim = ros_processes.start('sim_bridge', node(
        'sim_bridge', f'task:={TASK}', 'max_steps:=260', 'seed:=5', 'schedule.kind:=switch',
        'schedule.every:=100', 'schedule.values:=train', *start_gates('sim_bridge')))
    assert sim.wait(timeout=180) == 0, ros_processes.log_text('sim_bridge')[-3000:]
    time.sleep(1.5)
    ros_processes.stop(recorder, signal.SIGINT)
    assert collect.main(['--task', TASK, '--steps', '261', '--seed', '5', '--schedule',
                         'switch:train:every=100', '--checkpoint', str(checkpoint),
                         '--noise', '0', '--context-lag', str(lag),
                         '--out', str(tmp_path / 'collect'), '--no-progress']) == 0
    assert_ingests_as_one_by_one([bag_dir], monkeypatch)
    live = ingest_bags([bag_dir], strict=True).episodes
    local = ingest_bags([tmp_path / 'collect'], strict=True).episodes
    assert len(live) == len(local) == 1
    for field in ('steps', 'obs', 'action', 'reward', 'first', 'last', 'context', 'segment',
                  'stamps_ns'):
        a, b = getattr(live[0], field), getattr(local[0], field)
        assert a.shape == b.shape, field
        np.testing.assert_array_equal(a, b, err_msg=field)


def test_the_loop_waits_until_a_late_reader_hears_context_and_action(
        ros_processes: ProcessGroup, tmp_path) -> None:
    """expected_subscribers: no step before the estimator's and policy's readers match.

    A reader (a recorder's place) subscribes to zeus/step at once but to zeus/context and
    zeus/action only once the estimator says it is still waiting for them: it still gets
    every step's context and action from step 0. The estimator expects one reader more than
    comes: after subscriber_timeout it names the topic short of subscribers and starts anyway.
    """
    from zeus_msgs.msg import Action, ContextEstimate, StepFeedback

    from zeus_ros.nodes.topics import TOPICS, step_qos

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    got: dict[str, list[int]] = {'step': [], 'context': [], 'action': []}
    with driver_node(ros_processes.domain_id) as reader:
        reader.create_subscription(StepFeedback, TOPICS.STEP,
                                   lambda m: got['step'].append(m.step), step_qos(100))
        ros_processes.start('estimator', node(
            'context_estimator', f'checkpoint:={checkpoint}', 'expected_subscribers:=3',
            'subscriber_timeout:=8.0'))
        ros_processes.start('policy', node('policy', f'checkpoint:={checkpoint}',
                                           'expected_subscribers:=2'))
        sim = ros_processes.start('sim_bridge', bridge(40, 'min_observers:=3'))
        waiting = 'still waiting after 3 s: 3 subscribers of /zeus/context'
        assert spin_until(reader, lambda: waiting in ros_processes.log_text('estimator'), 90), \
            ros_processes.log_text('estimator')[-2000:]
        assert not got['step'], f'the loop started before its readers matched: {got}'
        reader.create_subscription(ContextEstimate, TOPICS.CONTEXT,
                                   lambda m: got['context'].append(m.step), step_qos(100))
        reader.create_subscription(Action, TOPICS.ACTION,
                                   lambda m: got['action'].append(m.step), step_qos(100))
        assert spin_until(reader, lambda: sim.poll() is not None and len(got['action']) > 40,
                          timeout=120), (got, ros_processes.log_text('sim_bridge')[-2000:])
    assert sim.returncode == 0
    for topic, steps in got.items():
        assert steps == list(range(41)), (topic, steps[:10])
    assert 'subscriber_timeout: 8 s passed waiting for 3 subscribers of /zeus/context ' \
        '(expected_subscribers; 2 matched so far)' in ros_processes.log_text('estimator')
