"""Fault matrix, live-parameter rows (issue 49): a local process cannot disarm the loop.

Real processes: sim_bridge and a seeded random policy in lockstep; a second process
(param_attacker.py, rclpy's AsyncParameterClient, as `ros2 param set`) sets sim_bridge's
`action_timeout` and the policy's `noise`. Before, any local process set `action_timeout :=
0.001` (1,166 of the next 1,217 steps ran the safe action) and `noise := 1.0` (4x the per-step
loss), logged as INFO. Now a value that would disarm the loop is refused with the reason; a
change in range is accepted, a WARN log line and a /diagnostics WARN with the old and new
value; with `lock_parameters:=true` every change of a safety-relevant parameter is refused as
read-only, while the policy's `checkpoint` (the continual trainer's redeploy) stays live.
"""

from __future__ import annotations

import json
from pathlib import Path
import sys
from typing import Any

import pytest

from live_fixtures import TASK, node
from ros_harness import ProcessGroup, driver_node, spin_until

pytestmark = pytest.mark.ros

ATTACKER = Path(__file__).with_name('param_attacker.py')


def _attack(group: ProcessGroup, label: str, target: str, *assignments: str
            ) -> dict[tuple[str, Any], dict[str, Any]]:
    """Run param_attacker.py against `target`; its answers by (name, value)."""
    process = group.start(label, [sys.executable, str(ATTACKER), target, *assignments])
    assert process.wait(timeout=45) == 0, group.log_text(label)
    answers = [json.loads(line) for line in group.log_text(label).splitlines()
               if line.startswith('{')]
    assert len(answers) == len(assignments), group.log_text(label)
    return {(a['name'], a['value']): a for a in answers}


def _start_loop(group: ProcessGroup, *extra: str) -> None:
    group.start('sim_bridge', node('sim_bridge', f'task:={TASK}', 'action_timeout:=0.5',
                                   'action_sender:=/policy', *extra))
    group.start('policy', node('policy', f'task:={TASK}', *extra))


def _warns(diagnostics: list[Any], name: str) -> list[str]:
    from diagnostic_msgs.msg import DiagnosticStatus

    return [s.message for array in diagnostics for s in array.status
            if s.name.startswith(f'/{name}:') and s.level >= DiagnosticStatus.WARN]


def test_a_disarming_value_is_refused_and_a_live_change_warns(
        ros_processes: ProcessGroup) -> None:
    """0.001 s and noise 1.0 refused with the reason; 1.0 s and 0.3 accepted, each a WARN."""
    from diagnostic_msgs.msg import DiagnosticArray
    from zeus_msgs.msg import StepFeedback

    from zeus_ros.nodes.topics import TOPICS, step_qos

    _start_loop(ros_processes)
    steps: list[StepFeedback] = []
    diagnostics: list[Any] = []
    with driver_node(ros_processes.domain_id) as probe:
        probe.create_subscription(StepFeedback, TOPICS.STEP, steps.append, step_qos(200))
        probe.create_subscription(DiagnosticArray, TOPICS.DIAGNOSTICS, diagnostics.append, 100)
        assert spin_until(probe, lambda: len(steps) > 20, 45), \
            ros_processes.log_text('sim_bridge')[-2000:]
        bridge = _attack(ros_processes, 'attacker-bridge', 'sim_bridge',
                         'action_timeout=0.001', 'action_timeout=1.0')
        policy = _attack(ros_processes, 'attacker-policy', 'policy', 'noise=1.0', 'noise=0.3')
        changed = len(steps)
        assert spin_until(probe, lambda: len(steps) > changed + 200 and any(
            'action_timeout changed live' in m for m in _warns(diagnostics, 'sim_bridge'))
            and any('noise changed live' in m for m in _warns(diagnostics, 'policy')), 30), \
            (len(steps) - changed, _warns(diagnostics, 'sim_bridge'),
             _warns(diagnostics, 'policy'))

    refused = bridge[('action_timeout', 0.001)]
    assert not refused['successful']
    # rclpy checks the descriptor's range before the node's callback: its words, our bound
    assert 'out of range Min: 0.1' in refused['reason'], refused
    assert bridge[('action_timeout', 1.0)]['successful'], bridge
    refused = policy[('noise', 1.0)]
    assert not refused['successful'] and 'Max: 0.5' in refused['reason'], refused
    assert policy[('noise', 0.3)]['successful'], policy
    after = steps[changed:]
    safe = sum(m.action_status != m.ACTION_OK for m in after)
    print(f'after the attack: {safe} of {len(after)} steps ran the safe action')
    # the loaded 2-core machine: a few slow answers may time out; 0.001 s made 96% safe
    assert safe <= 0.05 * len(after), f'{safe} of {len(after)} steps after the attack safe'
    warn = next(m for m in _warns(diagnostics, 'sim_bridge') if 'action_timeout' in m)
    assert '0.5 at start, now 1.0' in warn, warn
    warn = next(m for m in _warns(diagnostics, 'policy') if 'noise' in m)
    assert '0.0 at start, now 0.3' in warn, warn
    bridge_log = ros_processes.log_text('sim_bridge')
    assert 'WARN' in bridge_log and 'action_timeout changed live: 0.5 -> 1.0' in bridge_log
    assert 'noise changed live: 0.0 -> 0.3' in ros_processes.log_text('policy')


def test_with_lock_parameters_every_safety_change_is_refused_as_read_only(
        ros_processes: ProcessGroup) -> None:
    """lock_parameters:=true: read-only, refused whatever the value; checkpoint stays live."""
    from rclpy.parameter_client import AsyncParameterClient

    _start_loop(ros_processes, 'lock_parameters:=true')
    ros_processes.wait_for_log('sim_bridge', 'waiting for peers', 45)
    bridge = _attack(ros_processes, 'attacker-bridge', 'sim_bridge',
                     'action_timeout=0.001', 'action_timeout=0.2')
    policy = _attack(ros_processes, 'attacker-policy', 'policy', 'noise=1.0', 'noise=0.3')
    for answer in [*bridge.values(), *policy.values()]:
        assert not answer['successful'] and 'read-only' in answer['reason'], answer
    with driver_node(ros_processes.domain_id) as probe:
        client = AsyncParameterClient(probe, 'policy')
        assert client.wait_for_services(30)
        future = client.describe_parameters(['checkpoint', 'noise'])
        assert spin_until(probe, future.done, 20)
        checkpoint, noise = future.result().descriptors
        assert not checkpoint.read_only and noise.read_only
    assert 'changed live' not in ros_processes.log_text('sim_bridge')
