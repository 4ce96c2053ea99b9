"""Fault matrix, sender rows: only the paired policy drives, only its estimator informs it.

Real processes: sim_bridge (lockstep), a random policy, and a second process publishing on
zeus/action as fast as it can (flood_actions.py: well-formed actions for the awaited step,
NaN, Inf, 1e30, wrong lengths, wrong steps). None of its actions may be applied or even
validated, the loop keeps stepping, /diagnostics says ERROR while the intruder exists and
names it, and the log names it once. The same holds for contexts flooded at the policy.
"""

from __future__ import annotations

from collections.abc import Iterator
import contextlib
from pathlib import Path
import signal
import sys
import time
from typing import Any

import numpy as np
import pytest

from live_fixtures import TASK, node, tiny_checkpoint
from ros_harness import ProcessGroup, driver_node, spin_until

pytestmark = pytest.mark.ros

FLOODER = Path(__file__).with_name('flood_actions.py')
FLOOD_SECONDS = 5


def _bridge_statuses(diagnostics: list[Any]) -> list[Any]:
    return [s for array in diagnostics for s in array.status
            if s.name.lstrip('/').startswith('sim_bridge') and ': peer ' not in s.name]


def _watch(probe: Any, steps: list[tuple[float, Any]], diagnostics: list[Any]) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from zeus_msgs.msg import StepFeedback

    from zeus_ros.nodes.topics import TOPICS, step_qos

    probe.create_subscription(StepFeedback, TOPICS.STEP,
                              lambda m: steps.append((time.monotonic(), m)), step_qos(100))
    probe.create_subscription(DiagnosticArray, TOPICS.DIAGNOSTICS, diagnostics.append, 50)


@contextlib.contextmanager
def _stepping(group: ProcessGroup, min_steps: int, log_of: str
              ) -> Iterator[tuple[Any, list[tuple[float, Any]], list[Any]]]:
    """A probe watching the loop the test started, once it has made `min_steps` steps.

    Yields the probe, the (receipt time, StepFeedback) list and the /diagnostics list; the
    loop not getting there fails with the end of `log_of`'s log.
    """
    steps: list[tuple[float, Any]] = []
    diagnostics: list[Any] = []
    with driver_node(group.domain_id) as probe:
        _watch(probe, steps, diagnostics)
        assert spin_until(probe, lambda: len(steps) > min_steps, timeout=90), \
            group.log_text(log_of)[-2000:]
        yield probe, steps, diagnostics


def test_a_flooding_second_publisher_never_drives_the_robot(
        ros_processes: ProcessGroup) -> None:
    """Its actions are never applied, the loop keeps stepping, ERROR on /diagnostics, one log."""
    from diagnostic_msgs.msg import DiagnosticStatus
    from flood_actions import MARK
    from zeus_msgs.msg import StepFeedback

    ros_processes.start('sim_bridge', node('sim_bridge', f'task:={TASK}'))
    ros_processes.start('policy', node('policy', f'task:={TASK}'))
    with _stepping(ros_processes, 150, 'sim_bridge') as (probe, steps, diagnostics):
        calm = [t for t, _ in steps[50:]]
        calm_rate = (len(calm) - 1) / (calm[-1] - calm[0])
        flooder = ros_processes.start('intruder', [sys.executable, str(FLOODER),
                                                   str(FLOOD_SECONDS), '6'])
        assert spin_until(probe, lambda: 'flooding' in ros_processes.log_text('intruder'), 60)
        flood_start = time.monotonic()
        assert spin_until(probe, lambda: flooder.poll() is not None, FLOOD_SECONDS + 60)
        flood_end = time.monotonic()
        assert spin_until(probe, lambda: any(
            s.level == DiagnosticStatus.ERROR for s in _bridge_statuses(diagnostics)), 10)
        # Once the intruder has left the graph, the ERROR goes away.
        seen = len(diagnostics)
        assert spin_until(probe, lambda: any(
            s.level != DiagnosticStatus.ERROR for s in _bridge_statuses(diagnostics[seen:])),
            30), 'sim_bridge still reports ERROR after the intruder left'

    published = int(ros_processes.log_text('intruder').split('published ')[1].split()[0])
    flood = [(t, m) for t, m in steps if flood_start <= t <= flood_end]
    applied = np.asarray([m.applied_action for _, m in flood if len(m.applied_action)])
    assert len(flood) > 20 and published > 1000, (len(flood), published)
    assert not np.isclose(applied, MARK, atol=1e-6).all(axis=1).any(), 'an intruder drove'
    # No step waited out action_timeout (the 2 s stall of the issue): every step got the
    # policy's action. NONE: an episode's first step.
    statuses = {m.action_status for _, m in flood}
    assert statuses <= {StepFeedback.ACTION_OK, StepFeedback.ACTION_NONE}, \
        f'foreign actions reached the checks or the loop timed out: {statuses}'
    # The rate itself depends on what else shares the CPU (the intruder takes a core): printed,
    # not asserted; no step waiting out action_timeout (above) is the behaviour that matters.
    times = [t for t, _ in flood]
    flood_rate = (len(times) - 1) / (times[-1] - times[0])

    errors = [s for s in _bridge_statuses(diagnostics) if s.level == DiagnosticStatus.ERROR]
    # The first ERROR may come before the graph names the node ('a node not yet named').
    assert any('/intruder' in e.message and 'refused' in e.message for e in errors), \
        [e.message for e in errors]
    refused = max(int({kv.key: kv.value for kv in s.values}['foreign']) for s in errors)
    assert refused > 0
    log = ros_processes.log_text('sim_bridge')
    assert log.count('a second publisher on /zeus/action: /intruder') == 1, log[-3000:]
    print(f'flood: {published} actions in {FLOOD_SECONDS} s, {refused}+ refused, loop '
          f'{flood_rate:.0f} steps/s (calm {calm_rate:.0f}), longest step gap '
          f'{max(np.diff(times)) * 1000:.0f} ms')


@pytest.mark.ros_quiet
def test_a_restarted_policy_drives_again(ros_processes: ProcessGroup) -> None:
    """SIGKILL to the paired policy: safe actions (timeouts), then its restart is re-paired.

    Unkeyed (no $ZEUS_PAIRING_KEY here): only once the killed publisher has left the graph
    (its DDS lease, ~20 s), never merely because it fell silent (issue 49).
    """
    ros_processes.start('sim_bridge', node('sim_bridge', f'task:={TASK}',
                                           'action_timeout:=0.2'))
    policy = ros_processes.start('policy', node('policy', f'task:={TASK}'))
    with _stepping(ros_processes, 50, 'sim_bridge') as (probe, steps, _diagnostics):
        ros_processes.stop(policy, signal.SIGKILL)
        killed = len(steps)  # the probe may still be reading steps from before the kill
        assert spin_until(probe, lambda: sum(
            m.action_status != m.ACTION_OK for _, m in steps[killed:]) > 10, timeout=30)
        safe = next(i for i in range(killed, len(steps))
                    if steps[i][1].action_status != steps[i][1].ACTION_OK)
        ros_processes.start('policy2', node('policy', f'task:={TASK}'))
        assert spin_until(probe, lambda: sum(  # after the first safe step: only the restart's
            m.action_status == m.ACTION_OK for _, m in steps[safe:]) > 50, timeout=90), \
            ros_processes.log_text('sim_bridge')[-2000:]
    log = ros_processes.log_text('sim_bridge')
    assert '/policy restarted' in log and 'a second publisher' not in log, log[-2000:]
    assert 'left the graph)' in log and 'waits to drive' in log, log[-2000:]


def _status(diagnostics: list[Any], node_name: str) -> Any:
    """The newest /diagnostics status of `node_name` (None before the first)."""
    found = [s for array in diagnostics for s in array.status
             if s.name.lstrip('/').startswith(node_name) and ': peer ' not in s.name]
    return found[-1] if found else None


def test_a_second_context_publisher_never_reaches_the_policy(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """Contexts flooded on zeus/context by another process: refused by GID, ERROR, loop runs.

    The intruder's estimates carry no checkpoint sha256: had one reached the policy's checks it
    would count as `mismatched`; it must count as `foreign` instead.
    """
    from diagnostic_msgs.msg import DiagnosticStatus

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    ros_processes.start('sim_bridge', node('sim_bridge', f'task:={TASK}', 'min_observers:=2'))
    ros_processes.start('estimator', node('context_estimator', f'checkpoint:={checkpoint}'))
    ros_processes.start('policy', node('policy', f'checkpoint:={checkpoint}'))
    with _stepping(ros_processes, 100, 'policy') as (probe, steps, diagnostics):
        flooder = ros_processes.start('intruder', [sys.executable, str(FLOODER), '6', '4',
                                                   'context'])
        assert spin_until(probe, lambda: flooder.poll() is not None, 90)
        after = len(steps)
        assert spin_until(probe, lambda: len(steps) > after + 50, timeout=60), 'loop stopped'

        def policy_error() -> bool:
            status = _status(diagnostics, 'policy')
            return status is not None and status.level == DiagnosticStatus.ERROR

        if not policy_error():  # the intruder may already have left: look at the history
            assert any(s.level == DiagnosticStatus.ERROR and '/intruder' in s.message
                       for array in diagnostics for s in array.status
                       if s.name.lstrip('/').startswith('policy')), 'no ERROR on /diagnostics'
    values = {kv.key: kv.value for kv in _status(diagnostics, 'policy').values}
    assert int(values['foreign']) > 0 and int(values['mismatched']) == 0, values
    assert ros_processes.log_text('policy').count(
        'a second publisher on /zeus/context: /intruder') == 1


# make faults (21 s): with a 0.5 s settle it failed 4 of 10 runs here (sim_bridge, with no
# action_sender, paired with the first action publisher it discovered); with PAIRING_SETTLE_S
# 2.0 it passed 10 of 10 beside two trainings (senders.py).
@pytest.mark.faults_only
def test_two_action_publishers_at_start_wait_until_action_sender_names_one(
        ros_processes: ProcessGroup) -> None:
    """Two publishers before step 0: sim_bridge names both and waits; action_sender decides.

    With action_sender:=/policy it pairs with the policy and refuses the other.
    """
    from zeus_msgs.msg import Action

    from zeus_ros.nodes.topics import TOPICS, step_qos

    steps: list[tuple[float, Any]] = []
    diagnostics: list[Any] = []
    with driver_node(ros_processes.domain_id, name='stray') as probe:
        _watch(probe, steps, diagnostics)
        stray = probe.create_publisher(Action, TOPICS.ACTION, step_qos())
        ros_processes.start('policy', node('policy', f'task:={TASK}'))
        first = ros_processes.start('sim_bridge', node('sim_bridge', f'task:={TASK}'))
        assert spin_until(probe, lambda: 'found 2' in ros_processes.log_text('sim_bridge'),
                          60), ros_processes.log_text('sim_bridge')
        assert not steps, 'sim_bridge started with two action publishers:\n' + \
            ros_processes.log_text('sim_bridge')
        log = ros_processes.log_text('sim_bridge')
        assert '/policy' in log and '/stray' in log and 'set action_sender' in log, log
        ros_processes.stop(first)
        ros_processes.start('sim_bridge2', node('sim_bridge', f'task:={TASK}',
                                                'action_sender:=/policy'))
        assert spin_until(probe, lambda: len(steps) > 5, timeout=60), \
            ros_processes.log_text('sim_bridge2')

        def stray_is_named() -> bool:
            # keep sending until sim_bridge has refused one and named its node (the graph may
            # know the endpoint before its node name)
            stray.publish(Action(step=steps[-1][1].step, data=[0.4321] * 6))
            return 'a second publisher on /zeus/action: /stray' in \
                ros_processes.log_text('sim_bridge2')

        assert spin_until(probe, stray_is_named, timeout=30), \
            ros_processes.log_text('sim_bridge2')
        assert spin_until(probe, lambda: len(steps) > 100, timeout=60)
    log = ros_processes.log_text('sim_bridge2')
    assert 'paired with /policy' in log and 'a second publisher on /zeus/action: /stray' in log, \
        log
    statuses = [m.action_status for _, m in steps]
    assert set(statuses) <= {steps[0][1].ACTION_OK, steps[0][1].ACTION_NONE}, (statuses, log)
