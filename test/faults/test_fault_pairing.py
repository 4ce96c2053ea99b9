"""Fault matrix, pairing rows: every consumed topic has one sender; impostors are named.

Real processes: sim_bridge, context_estimator and policy (a tiny checkpoint) in lockstep, and
one after another, each while the loop runs: a foreign node named /policy while the real one
is paused for 2.5 s (the issue's spoof: it drove 482 of 483 steps), a foreign node named
/context_estimator stamping the pair's own checkpoint sha256, a node injecting observations
and steps, and a second sim_bridge on the same names. None of their messages is used; each is
an ERROR on /diagnostics naming it; the loop goes on with the real nodes.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
import signal
import sys
import time
from typing import Any

import numpy as np
import pytest

from live_fixtures import TASK, node, tiny_checkpoint
from ros_harness import ProcessGroup, driver_node, first_error_after, logged_at, spin_until

pytestmark = pytest.mark.ros

IMPOSTOR = Path(__file__).with_name('impostor.py')
NAMED_WITHIN_S = 5.0
"""A loose bound on attack -> ERROR naming the attacker (the issue's target, 2 s, is printed
and kept in docs/security.md: /diagnostics comes once a second and a loaded machine is slow)."""


def _errors(diagnostics: list[Any], name: str) -> list[str]:
    """Every ERROR message `name` (a node's fully qualified name) published."""
    from diagnostic_msgs.msg import DiagnosticStatus

    return [s.message for array in diagnostics for s in array.status
            if s.name.startswith(f'{name}: ') and s.level == DiagnosticStatus.ERROR]


def _newest(diagnostics: list[Any], name: str) -> dict[str, str]:
    found = [s for array in diagnostics for s in array.status  # the node's own, not its peers'
             if s.name.startswith(f'{name}: ') and ': peer ' not in s.name]
    return {kv.key: kv.value for kv in found[-1].values} if found else {}


def _pose(group: ProcessGroup, probe: Any, label: str, *args: str) -> float:
    """Run impostor.py with `args` to its end (the probe spins meanwhile); when it began."""
    process = group.start(label, [sys.executable, str(IMPOSTOR), *args])
    assert spin_until(probe, lambda: 'posing' in group.log_text(label), 60), \
        group.log_text(label)
    posing = time.time()
    assert spin_until(probe, lambda: process.poll() is not None, 60), group.log_text(label)
    assert 'published' in group.log_text(label), group.log_text(label)
    return posing


@pytest.mark.alone  # timing: see the alone marker (pyproject.toml)
def test_spoofed_injected_and_second_sources_are_refused_and_named(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """Name spoofing, context and observation injection, a second sim_bridge: all refused."""
    from diagnostic_msgs.msg import DiagnosticArray
    from impostor import INJECTED_STEP, MARK
    from zeus_msgs.msg import Action, StepFeedback

    from zeus_ros.nodes.topics import TOPICS, step_qos

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    sha256 = hashlib.sha256(checkpoint.read_bytes()).hexdigest()
    ros_processes.start('sim_bridge', node('sim_bridge', f'task:={TASK}', 'min_observers:=2',
                                           'action_timeout:=0.5'))
    ros_processes.start('estimator', node('context_estimator', f'checkpoint:={checkpoint}'))
    policy = ros_processes.start('policy', node('policy', f'checkpoint:={checkpoint}'))
    steps: list[StepFeedback] = []
    actions: list[int] = []
    diagnostics: list[Any] = []
    heard: list[float] = []  # wall clock each diagnostics array arrived

    def on_diagnostics(array: Any) -> None:
        diagnostics.append(array)
        heard.append(time.time())

    started = time.monotonic()
    with driver_node(ros_processes.domain_id) as probe:
        probe.create_subscription(StepFeedback, TOPICS.STEP, steps.append, step_qos(200))
        probe.create_subscription(Action, TOPICS.ACTION, lambda m: actions.append(m.step),
                                  step_qos(200))
        probe.create_subscription(DiagnosticArray, TOPICS.DIAGNOSTICS, on_diagnostics, 100)
        assert spin_until(probe, lambda: len(steps) > 60, 90), \
            ros_processes.log_text('sim_bridge')[-2000:]
        looping = time.monotonic()

        # 1. A foreign /policy while the real one is paused (SIGSTOP) for 2.5 s.
        spoof = ros_processes.start('fake_policy', [sys.executable, str(IMPOSTOR), 'policy',
                                                    'action', '6'])
        assert spin_until(probe, lambda: 'posing' in ros_processes.log_text('fake_policy'), 30)
        spoof_at = time.time()
        spin_until(probe, lambda: False, 0.5)
        os.kill(policy.pid, signal.SIGSTOP)
        try:
            spin_until(probe, lambda: False, 2.5)
        finally:
            os.kill(policy.pid, signal.SIGCONT)
        assert spin_until(probe, lambda: spoof.poll() is not None, 30)
        resumed = len(steps)
        assert spin_until(probe, lambda: sum(m.action_status == m.ACTION_OK
                                             for m in steps[resumed:]) > 20, 30), \
            'the real policy did not drive again after its pause'

        # 2. A foreign /context_estimator stamping the pair's own checkpoint sha256.
        fake_estimator_at = _pose(ros_processes, probe, 'fake_estimator', 'context_estimator',
                                  'context', '2', sha256)
        # 3. Observations and steps injected by another node.
        injector_at = _pose(ros_processes, probe, 'injector', 'intruder', 'observation', '3')
        # 4. A second sim_bridge on the same names (it stops after 5 unanswered steps).
        second = ros_processes.start('sim_bridge2', node(
            'sim_bridge', f'task:={TASK}', 'max_steps:=5', 'action_timeout:=0.3',
            'peer_grace:=0.0'))
        assert spin_until(probe, lambda: second.poll() is not None, 60), \
            ros_processes.log_text('sim_bridge2')[-2000:]
        before = len(steps)
        assert spin_until(probe, lambda: len(steps) > before + 30, 30), 'the loop stopped'
        spin_until(probe, lambda: False, 1.2)  # every node's next /diagnostics
    ended = time.monotonic()

    # How soon each attack was named on /diagnostics as ERROR (naming the attacker), from the
    # moment it posed (its publishers matched; the second bridge: it paired, then stepped).
    second_at = logged_at(ros_processes.log_text('sim_bridge2'), 'paired with')
    named = {
        'spoofed /policy at sim_bridge': first_error_after(
            diagnostics, heard, '/sim_bridge', 'same name as the paired node', spoof_at),
        'foreign /context_estimator at policy': first_error_after(
            diagnostics, heard, '/policy', '/zeus/context: /context_estimator', fake_estimator_at),
        'injector at estimator': first_error_after(
            diagnostics, heard, '/context_estimator', '/intruder', injector_at),
        'injector at policy': first_error_after(diagnostics, heard, '/policy', '/intruder',
                                           injector_at),
        'second sim_bridge at policy': first_error_after(
            diagnostics, heard, '/policy', '/zeus/step: /sim_bridge', second_at),
    }
    print('named as ERROR after (s): ' + ', '.join(f'{k} {v:.2f}' for k, v in named.items()))
    assert max(named.values()) < NAMED_WITHIN_S, named

    ours = [m for m in steps if m.step < INJECTED_STEP]
    applied = np.asarray([m.applied_action for m in ours if len(m.applied_action) == 6])
    marked = int(np.isclose(applied, MARK, atol=1e-6).all(axis=1).sum())
    assert marked == 0, f'{marked} steps applied an impostor action'
    assert not [s for s in actions if s >= INJECTED_STEP], 'the policy acted on an injection'
    # The second bridge's own steps: none answered (they all waited out action_timeout).
    log2 = ros_processes.log_text('sim_bridge2')
    assert "'ok': 0" in log2 and "'timeouts': 6" in log2, log2[-1500:]

    bridge = _errors(diagnostics, '/sim_bridge')
    assert any('/policy' in e and 'same name as the paired node' in e for e in bridge), bridge
    assert any('/clock' in e and 'besides this node' in e for e in bridge), bridge
    policy_errors = _errors(diagnostics, '/policy')
    estimator_errors = _errors(diagnostics, '/context_estimator')
    assert any('/zeus/context: /context_estimator' in e for e in policy_errors), policy_errors
    for name, errors in (('policy', policy_errors), ('estimator', estimator_errors)):
        assert any('/intruder' in e and 'refused' in e for e in errors), (name, errors)
        assert any('/zeus/step: /sim_bridge' in e for e in errors), (name, errors)
    values = _newest(diagnostics, '/policy')
    assert int(values['foreign']) > 0 and int(values['mismatched']) == 0, values
    assert int(_newest(diagnostics, '/context_estimator')['foreign']) > 0
    for label in ('policy', 'estimator'):
        assert 'a second publisher' in ros_processes.log_text(label)
    sent = {label: ros_processes.log_text(label).split('published ')[1].split()[0]
            for label in ('fake_policy', 'fake_estimator', 'injector')}
    bridge_values = _newest(diagnostics, '/sim_bridge')
    print(f'pairing rows: {marked} of {len(applied)} steps used an impostor action; sent '
          f'{sent}; refused: sim_bridge {bridge_values.get("foreign")}, estimator '
          f'{_newest(diagnostics, "/context_estimator")["foreign"]}, policy '
          f'{values["foreign"]}; the second sim_bridge: 0 of 6 steps answered; start-up '
          f'{looping - started:.1f} s, rows {ended - looping:.1f} s')


@pytest.mark.faults_only
def test_a_restart_without_the_launch_key_is_never_re_paired(ros_processes: ProcessGroup) -> None:
    """The paired policy is killed; a policy with another key takes its name: refused, named.

    The same node code, the same (random-policy) checkpoint, a fresh nonce: only the key's
    proof is missing. The restart with the launch's key is re-paired.
    """
    from zeus_msgs.msg import StepFeedback

    from zeus_ros.nodes.handshake import KEY_ENV
    from zeus_ros.nodes.topics import TOPICS, step_qos

    key = {KEY_ENV: 'a1' * 16}
    ros_processes.start('sim_bridge', node('sim_bridge', f'task:={TASK}', 'action_timeout:=0.2'),
                        key)
    policy = ros_processes.start('policy', node('policy', f'task:={TASK}'), key)
    steps: list[StepFeedback] = []
    with driver_node(ros_processes.domain_id) as probe:
        probe.create_subscription(StepFeedback, TOPICS.STEP, steps.append, step_qos(200))
        assert spin_until(probe, lambda: len(steps) > 50, 90)
        ros_processes.stop(policy, signal.SIGKILL)
        ros_processes.start('keyless', node('policy', f'task:={TASK}'), {KEY_ENV: 'b2' * 16})
        assert spin_until(probe, lambda: 'a second publisher on /zeus/action: /policy' in
                          ros_processes.log_text('sim_bridge'), 60), \
            ros_processes.log_text('sim_bridge')[-2000:]
        refused_from = len(steps)
        spin_until(probe, lambda: False, 2.0)
        refused = [m.action_status for m in steps[refused_from:]]
        ros_processes.start('rightful', node('policy', f'task:={TASK}'), key)
        restarted = len(steps)
        assert spin_until(probe, lambda: sum(m.action_status == m.ACTION_OK
                                             for m in steps[restarted:]) > 30, 90), \
            ros_processes.log_text('sim_bridge')[-2000:]
    log = ros_processes.log_text('sim_bridge')
    assert 'no valid proof of the launch key' in log, log[-2000:]
    assert refused and all(s != StepFeedback.ACTION_OK for s in refused), refused
    assert log.count('/policy restarted') == 1, log[-2000:]
    print(f'key row: {len(refused)} steps while the keyless policy published: none applied it')
