"""What a ROS user does next: namespaces, remaps, sim time, live parameters, Ctrl-C.

Real node processes, one fresh domain per test, loopback only, always cleaned up.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time
from typing import Any

import pytest

from live_fixtures import TASK, container, node, tiny_checkpoint
from ros_harness import (
    REPO,
    ProcessGroup,
    cpu_burners,
    driver_node,
    fresh_domain_id,
    python_module,
    read_until,
    ros_environment,
    spin_until,
    stop_launch,
)

pytestmark = pytest.mark.ros

MODULES = {'sim_bridge': 'sim_bridge_node', 'context_estimator': 'context_estimator_node',
           'policy': 'policy_node', 'recorder': 'recorder_node'}


def ros_node(name: str, *ros_args: str) -> list[str]:
    """The command line of a zeus_ros node followed by raw `--ros-args` arguments."""
    return python_module(f'zeus_ros.nodes.{MODULES[name]}', '--ros-args', *ros_args)


def final_counts(log: str) -> dict[str, int]:
    """sim_bridge's counts from its 'max_steps=N reached; counts {...}' line."""
    match = re.search(r'max_steps=\d+ reached; counts (\{.*\})', log)
    assert match, log[-2000:]
    return {k: int(v) for k, v in re.findall(r"'(\w+)': (\d+)", match.group(1))}


def newest_status(diagnostics: list[Any], name: str) -> dict[str, str]:
    """Key/values of the newest /diagnostics status whose name starts with `name`."""
    for array in reversed(diagnostics):
        for status in array.status:
            if status.name.startswith(name):
                return {kv.key: kv.value for kv in status.values}
    return {}


def test_two_namespaced_systems_in_one_domain_run_without_crosstalk(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """/r1 and /r2 with use_sim_time: 200 lockstep steps each, own schedule, no crosstalk.

    One params file with `/**/node:` keys configures both; each system's schedule comes from a
    `/rN/sim_bridge:` section. Two simulators in one domain each remap /clock into their
    namespace, as a ROS user would.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from zeus_msgs.msg import ContextTruth

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    values = {'r1': [0.6, 1.0], 'r2': [1.3, 1.5]}
    params = tmp_path / 'params.yaml'
    params.write_text(
        '/**/sim_bridge:\n  ros__parameters:\n'
        f'    task: {TASK}\n    max_steps: 200\n    min_observers: 2\n    action_timeout: 5.0\n'
        + ''.join(f'/{ns}/sim_bridge:\n  ros__parameters:\n    schedule:\n      kind: switch\n'
                  f'      every: 50\n      values: {vals}\n' for ns, vals in values.items())
        + ''.join(f'/**/{name}:\n  ros__parameters:\n    checkpoint: {checkpoint}\n'
                  f'    task: {TASK}\n' for name in ('context_estimator', 'policy')))
    bridges = {}
    for ns in values:
        common = ['-r', f'__ns:=/{ns}', '-r', f'/clock:=/{ns}/clock', '-p', 'use_sim_time:=true',
                  '--params-file', str(params)]
        bridges[ns] = ros_processes.start(f'{ns}-sim_bridge', ros_node('sim_bridge', *common))
        for name in ('context_estimator', 'policy'):
            ros_processes.start(f'{ns}-{name}', ros_node(name, *common))
    truths: dict[str, dict[int, float]] = {ns: {} for ns in values}
    diagnostics: list[Any] = []
    with driver_node(ros_processes.domain_id) as probe:
        from zeus_ros.nodes.topics import step_qos

        for ns in values:
            probe.create_subscription(
                ContextTruth, f'/{ns}/zeus/context_truth',
                lambda m, ns=ns: truths[ns].__setitem__(m.step, m.values[0]), step_qos(300))
        probe.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 100)
        done = spin_until(probe, lambda: all(b.poll() is not None for b in bridges.values()),
                          timeout=180)
        assert done, ros_processes.log_text('r1-sim_bridge')[-2000:]
        spin_until(probe, lambda: False, timeout=1.5)  # the estimators' final diagnostics
    for ns, bridge in bridges.items():
        assert bridge.returncode == 0, ros_processes.log_text(f'{ns}-sim_bridge')[-2000:]
        counts = final_counts(ros_processes.log_text(f'{ns}-sim_bridge'))
        assert counts['steps'] == 201 and counts['ok'] == 200, counts
        assert counts['unexpected'] == 0 and counts['timeouts'] == 0, counts
        assert truths[ns], f'no truth seen on /{ns}'
        assert {round(v, 3) for v in truths[ns].values()} <= set(values[ns]), truths[ns]
        estimator = newest_status(diagnostics, f'/{ns}/context_estimator')
        assert estimator.get('gaps') == '0' and estimator.get('estimates') == '201', estimator
        policy = newest_status(diagnostics, f'/{ns}/policy')
        assert policy.get('actions') == '201' and policy.get('safe') == '0', policy
    stamps = [array.header.stamp.sec for array in diagnostics
              if array.status[0].name.startswith('/r1/policy')]
    assert stamps and max(stamps) < 3600, 'the policy does not run on simulation time'


def test_a_remapped_action_topic_runs_the_loop_and_a_wait_says_why(
        ros_processes: ProcessGroup) -> None:
    """`-r zeus/action:=cmd` on both ends: sim_bridge first names what it waits for, then runs."""
    remap = ('-r', 'zeus/action:=cmd')
    bridge = ros_processes.start('remap-sim_bridge', ros_node(
        'sim_bridge', *remap, '-p', f'task:={TASK}', '-p', 'max_steps:=100'))
    ros_processes.wait_for_log('remap-sim_bridge', 'still waiting after', timeout=60)
    waiting = ros_processes.log_text('remap-sim_bridge')
    assert 'a policy publishing on /cmd' in waiting, waiting
    ros_processes.start('remap-policy', ros_node('policy', *remap, '-p', f'task:={TASK}'))
    assert bridge.wait(timeout=120) == 0, ros_processes.log_text('remap-sim_bridge')[-2000:]
    counts = final_counts(ros_processes.log_text('remap-sim_bridge'))
    assert counts['ok'] == 100 and counts['unexpected'] == 0 and counts['timeouts'] == 0


def test_the_loop_waits_for_its_named_observers_not_for_any_subscriber(
        ros_processes: ProcessGroup) -> None:
    """`observers`: a bystander on zeus/step (`ros2 topic echo`, a status line) is no stand-in.

    min_observers (2) is met by the policy and the bystander, yet no step is published until
    the node named in `observers` subscribes; then the loop runs and the bystander sees step 0.
    """
    from zeus_msgs.msg import StepFeedback

    from zeus_ros.nodes.topics import step_qos

    bridge = ros_processes.start('observers-sim_bridge', ros_node(
        'sim_bridge', '-p', f'task:={TASK}', '-p', 'max_steps:=50', '-p', 'min_observers:=2',
        '-p', "observers:=['policy','watcher']"))
    ros_processes.start('observers-policy', ros_node('policy', '-p', f'task:={TASK}'))
    seen: list[int] = []
    with driver_node(ros_processes.domain_id, name='bystander') as bystander:
        bystander.create_subscription(StepFeedback, '/zeus/step', lambda m: seen.append(m.step),
                                      step_qos(100))
        assert spin_until(bystander, lambda: bystander.count_subscribers('/zeus/step') >= 2,
                          timeout=60), 'the policy never subscribed to /zeus/step'
        spin_until(bystander, lambda: bool(seen), timeout=4.0)  # longer than peer_grace
        assert not seen, f'steps {seen[:5]} published before the named observer subscribed'
        assert 'watcher subscribed to /zeus/step (observers)' in \
            ros_processes.log_text('observers-sim_bridge')
        with driver_node(ros_processes.domain_id, name='watcher') as watcher:
            watcher.create_subscription(StepFeedback, '/zeus/step', lambda m: None, step_qos())
            assert spin_until(bystander, lambda: bridge.poll() is not None, timeout=120), \
                ros_processes.log_text('observers-sim_bridge')[-2000:]
    assert bridge.returncode == 0, ros_processes.log_text('observers-sim_bridge')[-2000:]
    assert seen and seen[0] == 0, seen[:5]
    assert final_counts(ros_processes.log_text('observers-sim_bridge'))['ok'] == 50


def call(node: Any, future: Any, timeout: float = 20.0) -> Any:
    """Spin until a parameter-service future is done; its result."""
    assert spin_until(node, future.done, timeout), 'no answer from the parameter service'
    return future.result()


@pytest.mark.parametrize('single_process', [False, True], ids=['processes', 'one_process'])
def test_live_parameters_apply_or_are_refused_with_the_reason(
        ros_processes: ProcessGroup, tmp_path: Path, single_process: bool) -> None:
    """Through rclpy's parameter services: describe, refuse bad values, apply good ones live.

    The policy's `noise` is measured on the next actions (they leave the deterministic action),
    sim_bridge's `max_steps` on where the loop stops. The same holds with both nodes in one
    process (the container of `zeus launch --single-process`).
    """
    import numpy as np
    from rcl_interfaces.msg import ParameterType
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    import torch
    from zeus_msgs.msg import Action, StateVector

    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.nodes.topics import step_qos

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt', method='no_context')
    params = {'sim_bridge': (f'task:={TASK}', 'action_timeout:=5.0'),
              'policy': (f'checkpoint:={checkpoint}',)}
    if single_process:  # the log of both nodes is the container's: read as sim_bridge's
        bridge = ros_processes.start('live-sim_bridge', container(params))
    else:
        bridge = ros_processes.start('live-sim_bridge', node('sim_bridge', *params['sim_bridge']))
        ros_processes.start('live-policy', node('policy', *params['policy']))
    torch.set_num_threads(1)
    agent = InferenceAgent.from_checkpoint(checkpoint)
    states: dict[int, Any] = {}
    gaps: dict[int, float] = {}

    def on_action(msg: Any) -> None:
        if msg.step in states:
            expected = agent.act(states[msg.step], np.zeros(0, np.float32), deterministic=True)
            gaps[msg.step] = float(np.abs(expected - np.asarray(msg.data)).max())

    with driver_node(ros_processes.domain_id) as probe:
        probe.create_subscription(StateVector, 'zeus/observation/state',
                                  lambda m: states.__setitem__(
                                      m.step, np.asarray(m.data, np.float32)),
                                  step_qos(100))
        probe.create_subscription(Action, 'zeus/action', on_action, step_qos(100))
        policy = AsyncParameterClient(probe, 'policy')
        bridge_params = AsyncParameterClient(probe, 'sim_bridge')
        assert policy.wait_for_services(30) and bridge_params.wait_for_services(30)
        assert spin_until(probe, lambda: len(gaps) > 20, timeout=60)
        assert max(gaps.values()) < 1e-4, 'deterministic actions should match the checkpoint'

        described = call(probe, policy.describe_parameters(['noise', 'mode'])).descriptors
        assert 'noise' in described[0].description
        assert described[0].floating_point_range[0].to_value == pytest.approx(0.5)  # NOISE_MAX
        assert described[1].read_only and 'lockstep' in described[1].additional_constraints

        refused = {
            'context_deadline': Parameter('context_deadline', value=-3.0),
            'frozen_context': Parameter('frozen_context', value='banana'),
            'mode': Parameter('mode', value='banana'),
            'context_lag': Parameter('context_lag', value=99),
        }
        results = call(probe, policy.set_parameters(list(refused.values()))).results
        for (name, _), result in zip(refused.items(), results, strict=True):
            assert not result.successful and result.reason, name
        assert 'frozen_context' in results[1].reason and 'numbers' in results[1].reason
        assert 'read-only' in results[2].reason
        assert 'Max: 16' in results[3].reason, results[3].reason
        kept = call(probe, policy.get_parameters(['context_deadline', 'mode'])).values
        assert kept[0].double_value == pytest.approx(0.2) and kept[1].string_value == 'lockstep'

        result = call(probe, policy.set_parameters([Parameter('noise', value=0.5)])).results[0]
        assert result.successful, result.reason
        changed_at = max(states)  # the probe may lag the loop: find where noise starts

        def first_noisy() -> int | None:
            return min((s for s, g in gaps.items() if s > changed_at and g > 1e-3), default=None)

        assert spin_until(probe, lambda: first_noisy() is not None and len(
            [s for s in gaps if s > first_noisy()]) > 20, 60), 'noise=0.5 never reached actions'
        start = first_noisy()
        noisy = np.asarray([gap for step, gap in gaps.items() if step > start])
        # an action already at its bound can be clipped back onto it in every dimension
        assert np.mean(noisy > 1e-3) > 0.8, f'actions after the change not noisy: {noisy}'

        refused_type = call(probe, bridge_params.set_parameters(
            [Parameter('action_timeout', value='soon')])).results[0]
        assert not refused_type.successful and refused_type.reason
        # Last call to sim_bridge: the loop may be more than 30 steps ahead of the probe (in
        # one process it runs hundreds of steps per second) and stop at once, services and all.
        stop_at = max(states) + 30
        result = call(probe, bridge_params.set_parameters(
            [Parameter('max_steps', value=stop_at)])).results[0]
        assert result.successful, result.reason
        assert spin_until(probe, lambda: bridge.poll() is not None, timeout=60)
    assert bridge.returncode == 0
    assert f'max_steps={stop_at} reached' in ros_processes.log_text('live-sim_bridge')
    assert kept[0].type == ParameterType.PARAMETER_DOUBLE


@pytest.mark.parametrize('single_process', [False, True], ids=['processes', 'one_process'])
def test_one_sigint_stops_zeus_launch_record_cleanly(tmp_path: Path, single_process: bool
                                                     ) -> None:
    """SIGINT to `zeus launch --record`: all exit 0 within 3 s, no traceback, a closed bag.

    The group starts on a machine whose every core is kept busy, in namespace /r7 on
    simulation time, as separate processes or with the loop in one; the bag has its final
    metadata and the steps sim_bridge published, with their context and action, from step 0 to
    the last, under the schema's topic names (as processes without a gap).
    """
    from rosbags.highlevel import AnyReader

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    out = tmp_path / 'bag'
    params = tmp_path / 'params.yaml'
    params.write_text(
        f'/**/sim_bridge:\n  ros__parameters:\n    task: {TASK}\n    log_every: 100\n'
        + ''.join(f'/**/{name}:\n  ros__parameters:\n    checkpoint: {checkpoint}\n'
                  f'    task: {TASK}\n' for name in ('context_estimator', 'policy'))
        + f'/**/recorder:\n  ros__parameters:\n    output: {out}\n')
    lines: list[str] = []
    with cpu_burners():  # start-up under load: discovery and matching at their slowest
        launch = subprocess.Popen(
            [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params', str(params),
             '--record', '--namespace', 'r7', '--sim-time',
             *(['--single-process'] if single_process else [])],
            cwd=REPO, env=ros_environment(fresh_domain_id()), stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, start_new_session=True)
        try:
            read_until(launch, '/zeus/step: first message at step', lines, timeout=180)
        except BaseException:
            stop_launch(launch)
            raise
    try:  # then running and stopping as a user's Ctrl-C would
        read_until(launch, 'step 200 ', lines)
        signalled = time.monotonic()
        os.killpg(launch.pid, signal.SIGINT)
        rest = launch.communicate(timeout=30)[0]
        stopped_in = time.monotonic() - signalled
    finally:
        stop_launch(launch)
    output = ''.join(lines) + rest
    assert launch.returncode == 0, output[-3000:]
    # ros2 launch escalates to SIGTERM after sigterm_timeout (5 s): a clean Ctrl-C ends before
    # it. Measured here 1-2 s, once 4.8 s in a full CI run (cause not found; the output
    # after the signal is in the message).
    assert stopped_in < 5.0, f'stopping took {stopped_in:.1f} s:\n{rest}'
    codes = re.search(r'exit codes: (.*)', output)
    assert codes and codes.group(1).strip() == (
        'container 0, recorder 0' if single_process else
        'sim_bridge 0, context_estimator 0, policy 0, recorder 0'), output[-2000:]
    assert 'Traceback' not in output and 'KeyboardInterrupt' not in output, output[-3000:]
    bag = out / f'{out.name}_000'
    metadata = (bag / 'metadata.yaml').read_text()
    assert re.search(r'zeus_bag_state: .?closed', metadata), metadata
    steps: dict[str, list[int]] = {}
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            if conn.topic in ('/zeus/step', '/zeus/context', '/zeus/action'):
                step = int(reader.deserialize(raw, conn.msgtype).step)
                steps.setdefault(conn.topic, []).append(step)
    recorded = sorted(steps['/zeus/step'])
    last = re.search(r'stopped after step (\d+)', output)
    assert last, output[-2000:]
    published = list(range(int(last.group(1)) + 1))
    # From step 0 to the last step published: nothing lost at either end. The one-process loop
    # runs at ~130 steps/s here, and a recorder more than the publishers' history (10 steps)
    # behind loses steps mid-run (README, QoS); it counts and names each one, none goes silently.
    gaps = re.search(r"step gaps .*'/zeus/step': (\d+)", output)
    lost = int(gaps.group(1)) if gaps else 0
    assert recorded[0] == 0 and recorded[-1] == published[-1], output[-2000:]
    assert set(recorded) <= set(published) and len(recorded) + lost == len(published), \
        output[-2000:]
    assert single_process or not lost, output[-2000:]
    # Every node's answer from step 0 (expected_subscribers: estimator and policy subscribe to
    # the steps only once the recorder hears them; expected_publishers: the recorder only once
    # it hears them); Ctrl-C may cut the last step's answers.
    assert '/zeus/step: first message at step 0' in output, output[-3000:]
    for topic in ('/zeus/context', '/zeus/action'):
        unanswered = set(recorded[:-1]) - set(steps[topic])
        assert min(steps[topic]) == 0 and not unanswered, \
            f'{topic}: steps {sorted(unanswered)[:10]} unanswered in the bag\n{output[-6000:]}'


@pytest.mark.parametrize(('name', 'params'), [
    ('policy', ('task:=Cheetah-Run-v0', 'noize:=0.1')),
    ('context_estimator', ('checkpoint:=missing.pt', 'noize:=0.1')),
])
def test_an_unknown_parameter_stops_the_node_at_start(
        ros_processes: ProcessGroup, name: str, params: tuple[str, ...]) -> None:
    """A typo in a parameter name is an error (exit 2 naming it), never silently ignored."""
    args = [arg for param in params for arg in ('-p', param)]
    process = ros_processes.start(f'unknown-{name}', ros_node(name, *args))
    assert process.wait(timeout=60) == 2
    log = ros_processes.log_text(f'unknown-{name}')
    assert 'unknown parameter' in log and 'noize' in log and 'Traceback' not in log, log


LAUNCH_SIGTERM_TIMEOUT_S = 5.0
"""launch's default sigterm_timeout: how long `ros2 launch` waits after SIGINT before SIGTERM."""


def test_two_sigints_to_every_node_like_ros2_launch_leave_a_closed_bag(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """Ctrl-C in a terminal on `ros2 launch`: every node gets SIGINT, then the launch's own.

    Each node exits 0 without a traceback before launch would escalate to SIGTERM (its
    sigterm_timeout, 5 s), and the recorder still closes its bag.
    """
    from rosbags.highlevel import AnyReader

    from zeus_ros.nodes.spin import STACKS_SIGNAL

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    out = tmp_path / 'bag'
    agent = ('-p', f'checkpoint:={checkpoint}', '-p', f'task:={TASK}')
    nodes = {
        'sim_bridge': ros_node('sim_bridge', '-p', f'task:={TASK}', '-p', 'log_every:=100',
                               '-p', 'min_observers:=3'),
        'context_estimator': ros_node('context_estimator', *agent),
        'policy': ros_node('policy', *agent),
        'recorder': ros_node('recorder', '-p', f'output:={out}'),
    }
    processes = {name: ros_processes.start(f'sigint2-{name}', argv)
                 for name, argv in nodes.items()}
    ros_processes.wait_for_log('sigint2-sim_bridge', 'step 100 ', timeout=90)
    signalled = time.monotonic()
    for _ in range(2):
        for process in processes.values():
            os.killpg(process.pid, signal.SIGINT)
        time.sleep(0.05)
    deadline = signalled + LAUNCH_SIGTERM_TIMEOUT_S
    for name, process in processes.items():
        try:
            code = process.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            os.kill(process.pid, STACKS_SIGNAL)  # where it is stuck, into its log
            time.sleep(1.0)
            pytest.fail(f'{name} still running {LAUNCH_SIGTERM_TIMEOUT_S} s after two SIGINTs:'
                        f'\n{ros_processes.log_text(f"sigint2-{name}")[-6000:]}')
        log = ros_processes.log_text(f'sigint2-{name}')
        assert code == 0 and 'Traceback' not in log, f'{name} exited {code}:\n{log[-2000:]}'
    bag = out / f'{out.name}_000'
    assert re.search(r'zeus_bag_state: .?closed', (bag / 'metadata.yaml').read_text())
    with AnyReader([bag]) as reader:
        recorded = sorted(int(reader.deserialize(raw, conn.msgtype).step)
                          for conn, _, raw in reader.messages() if conn.topic == '/zeus/step')
    assert len(recorded) > 100 and recorded == list(range(len(recorded)))


def test_sigusr1_prints_every_thread_s_stack_and_the_node_runs_on(
        ros_processes: ProcessGroup) -> None:
    """`kill -USR1 <pid>`: the node's threads' Python stacks in its log; SIGINT still stops it."""
    from zeus_ros.nodes.spin import STACKS_SIGNAL

    policy = ros_processes.start('usr1-policy', ros_node('policy', '-p', f'task:={TASK}'))
    ros_processes.wait_for_log('usr1-policy', 'random policy', timeout=60)
    os.kill(policy.pid, STACKS_SIGNAL)
    ros_processes.wait_for_log('usr1-policy', 'Current thread', timeout=10)
    assert 'run_nodes' in ros_processes.log_text('usr1-policy')
    time.sleep(0.5)
    assert policy.poll() is None
    assert ros_processes.stop(policy) == 0


def test_live_checkpoint_redeploy_swaps_the_pair_and_never_mixes_it(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """`checkpoint` set live on policy, then estimator: no restart, the loop keeps running.

    While only the policy has the new checkpoint it refuses the old estimator's contexts
    (counted `mismatched`, safe actions); once both have it, estimates carry its sha256 and the
    actions are the new checkpoint's. Both log its absolute path and sha256; a missing file is
    refused with the reason.
    """
    import hashlib

    from diagnostic_msgs.msg import DiagnosticArray
    import numpy as np
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    import torch
    from zeus_msgs.msg import Action, ContextEstimate, StateVector

    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.nodes.topics import step_qos

    old, new = tiny_checkpoint(tmp_path / 'old.pt'), tiny_checkpoint(tmp_path / 'new.pt', seed=1)
    sha = {path: hashlib.sha256(path.read_bytes()).hexdigest() for path in (old, new)}
    assert sha[old] != sha[new]
    ros_processes.start('swap-sim_bridge', ros_node(
        'sim_bridge', '-p', f'task:={TASK}', '-p', 'min_observers:=2', '-p',
        'action_timeout:=5.0'))
    for name in ('context_estimator', 'policy'):
        ros_processes.start(f'swap-{name}', ros_node(name, '-p', f'checkpoint:={old}'))
    torch.set_num_threads(1)
    agent = InferenceAgent.from_checkpoint(new)
    states: dict[int, Any] = {}
    contexts: dict[int, tuple[str, Any]] = {}
    actions: dict[int, Any] = {}
    diagnostics: list[Any] = []
    with driver_node(ros_processes.domain_id) as probe:
        probe.create_subscription(StateVector, 'zeus/observation/state',
                                  lambda m: states.__setitem__(
                                      m.step, np.asarray(m.data, np.float32)), step_qos(100))
        probe.create_subscription(ContextEstimate, 'zeus/context', lambda m: contexts.__setitem__(
            m.step, (m.checkpoint_sha256, np.asarray(m.data, np.float32))), step_qos(100))
        probe.create_subscription(Action, 'zeus/action', lambda m: actions.__setitem__(
            m.step, np.asarray(m.data, np.float32)), step_qos(100))
        probe.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 50)
        clients = {name: AsyncParameterClient(probe, name)
                   for name in ('policy', 'context_estimator')}
        assert all(client.wait_for_services(30) for client in clients.values())
        assert spin_until(probe, lambda: len(contexts) > 20, timeout=60)
        assert {s for s, _ in contexts.values()} == {sha[old]}

        refused = call(probe, clients['policy'].set_parameters(
            [Parameter('checkpoint', value=str(tmp_path / 'missing.pt'))])).results[0]
        assert not refused.successful and 'missing.pt' in refused.reason, refused.reason
        result = call(probe, clients['policy'].set_parameters(
            [Parameter('checkpoint', value=str(new))]), timeout=60).results[0]
        assert result.successful, result.reason

        def policy_counts() -> dict[str, str]:
            return newest_status(diagnostics, '/policy')

        assert spin_until(probe, lambda: int(policy_counts().get('mismatched', 0)) > 0
                          and int(policy_counts().get('safe', 0)) > 0, timeout=30)
        asked = time.monotonic()
        result = call(probe, clients['context_estimator'].set_parameters(
            [Parameter('checkpoint', value=str(new))]), timeout=60).results[0]
        swap_s = time.monotonic() - asked
        assert result.successful, result.reason
        assert swap_s < 5.0, f'the estimator took {swap_s:.2f} s to load and swap'
        assert spin_until(probe, lambda: any(s == sha[new] for s, _ in contexts.values()), 30)
        first_new = min(step for step, (s, _) in contexts.items() if s == sha[new])
        assert spin_until(probe, lambda: len([s for s in actions if s > first_new + 5]) > 20, 60)
        reports: list[dict[str, str]] = []

        def next_report() -> dict[str, str]:
            """The policy's status from a /diagnostics message that arrives from now on."""
            seen = len(diagnostics)
            assert spin_until(probe, lambda: newest_status(diagnostics[seen:], '/policy'), 5)
            reports.append(newest_status(diagnostics[seen:], '/policy'))
            return reports[-1]

        next_report()  # may have been taken before the last old estimate was refused
        mismatched = next_report()['mismatched']
        next_report()
        assert next_report()['mismatched'] == mismatched, f'still refusing: {reports}'
    assert all(s == sha[new] for step, (s, _) in contexts.items() if step >= first_new)
    checked = [step for step in actions if step > first_new + 5 and step in contexts
               and step in states]
    assert len(checked) > 10
    for step in checked:
        expected = agent.act(states[step], contexts[step][1], deterministic=True)
        np.testing.assert_allclose(actions[step], expected, atol=1e-4, err_msg=f'step {step}')
    for name in ('context_estimator', 'policy'):
        log = ros_processes.log_text(f'swap-{name}')
        assert f'loaded {old} (sha256 {sha[old]})' in log, log[-2000:]
        assert f'redeployed live: zeus checkpoint {new} (sha256 {sha[new]})' in log, log[-2000:]
