"""Managed nodes with real processes: policy and estimator walked through their lifecycle.

A lockstep loop whose policy starts with `autostart:=false`: unconfigured, no action reaches
sim_bridge (every step's status is the timeout's safe action); configure + activate, the
policy's actions are applied; deactivate, none are; activate again, they are applied again on
the same publisher (sim_bridge's pairing holds, nothing foreign). The estimator, on the
default `autostart`, reports 'active'; both appear as `ros2 lifecycle nodes` finds them (a
`~/get_state` service of type lifecycle_msgs/srv/GetState). In the one-process container, a
policy left unconfigured holds the loop (sim_bridge waits for an action publisher) until it is
configured and activated by service.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from live_fixtures import TASK, container, node, tiny_checkpoint
from ros_harness import ProcessGroup, driver_node, fresh_domain_id, ros_context, spin_until

pytestmark = pytest.mark.ros

MANAGED = ('/policy', '/context_estimator')
ACTION_TIMEOUT = 0.2
"""sim_bridge's action_timeout: steps go on at ~5 Hz on the safe action while nobody acts."""


def _call(probe: Any, client: Any, request: Any, timeout: float = 20.0) -> Any:
    future = client.call_async(request)
    assert spin_until(probe, future.done, timeout), f'no answer from {client.srv_name}'
    return future.result()


def test_policy_lifecycle_gates_the_actions_sim_bridge_applies(ros_processes: ProcessGroup,
                                                               tmp_path: Path) -> None:
    """unconfigured: no action; active: applied; inactive: none; active again: applied."""
    from diagnostic_msgs.msg import DiagnosticArray
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState
    from test_ros_citizen import newest_status
    from zeus_msgs.msg import Action, StepFeedback

    from sim_bridge.actions import ActionStatus
    from zeus_ros.nodes.topics import step_qos

    APPLIED = (ActionStatus.OK, ActionStatus.CLIPPED)  # noqa: N806 - the policy's action
    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    # No waiting for peers: sim_bridge steps on its safe action while the policy is not active.
    ros_processes.start('lc-sim_bridge', node('sim_bridge', f'task:={TASK}',
                                              'wait_for_peers:=false',
                                              f'action_timeout:={ACTION_TIMEOUT}'))
    ros_processes.start('lc-context_estimator', node('context_estimator',
                                                     f'checkpoint:={checkpoint}'))
    ros_processes.start('lc-policy', node('policy', f'checkpoint:={checkpoint}',
                                          'autostart:=false'))
    status: dict[int, int] = {}  # step -> action_status of the action applied before it
    actions: dict[int, list[float]] = {}
    diagnostics: list[Any] = []
    with driver_node(ros_processes.domain_id) as probe:
        probe.create_subscription(StepFeedback, 'zeus/step', lambda m: status.__setitem__(
            m.step, m.action_status), step_qos(100))
        probe.create_subscription(Action, 'zeus/action', lambda m: actions.__setitem__(
            m.step, list(m.data)), step_qos(100))
        probe.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 50)
        get = {name: probe.create_client(GetState, f'{name}/get_state') for name in MANAGED}
        change = probe.create_client(ChangeState, '/policy/change_state')
        assert all(c.wait_for_service(timeout_sec=60) for c in [*get.values(), change]), \
            ros_processes.log_text('lc-policy')[-2000:]
        listed = dict(probe.get_service_names_and_types())
        assert all(listed.get(f'{name}/get_state') == ['lifecycle_msgs/srv/GetState']
                   for name in MANAGED), listed

        def state(name: str = '/policy') -> str:
            return str(_call(probe, get[name], GetState.Request()).current_state.label)

        def transition(transition_id: int) -> None:
            answer = _call(probe, change, ChangeState.Request(
                transition=Transition(id=transition_id)))
            assert answer.success, ros_processes.log_text('lc-policy')[-2000:]

        def steps_after(mark: int, count: int) -> list[int]:
            """Wait for `count` steps after `mark` (at least `ACTION_TIMEOUT` each)."""
            assert spin_until(probe, lambda: len([s for s in status if s > mark]) >= count,
                              timeout=30), ros_processes.log_text('lc-sim_bridge')[-2000:]
            return sorted(s for s in status if s > mark)

        assert state('/context_estimator') == 'active'  # autostart (the default)
        assert state() == 'unconfigured'
        unconfigured = steps_after(0, 5)
        assert not actions
        assert {status[s] for s in unconfigured[1:]} == {ActionStatus.TIMEOUT}

        transition(Transition.TRANSITION_CONFIGURE)
        assert state() == 'inactive'
        mark = max(status)
        inactive = steps_after(mark, 3)
        assert not actions and {status[s] for s in inactive} == {ActionStatus.TIMEOUT}

        transition(Transition.TRANSITION_ACTIVATE)
        assert state() == 'active'
        assert spin_until(probe, lambda: any(
            s - 1 in actions and status[s] in APPLIED for s in status), timeout=30), \
            ros_processes.log_text('lc-policy')[-2000:]

        transition(Transition.TRANSITION_DEACTIVATE)
        assert state() == 'inactive'
        spin_until(probe, lambda: False, timeout=1.0)  # the probe catches up with the loop
        mark = max(status)
        after = steps_after(mark + 1, 4)
        assert not [s for s in actions if s > mark], sorted(actions)[-5:]
        assert {status[s] for s in after} == {ActionStatus.TIMEOUT}

        transition(Transition.TRANSITION_ACTIVATE)
        assert state() == 'active'
        mark = max(status)
        assert spin_until(probe, lambda: len([
            s for s in status if s > mark + 1 and s - 1 in actions
            and status[s] in APPLIED]) >= 10, timeout=30), \
            ros_processes.log_text('lc-sim_bridge')[-2000:]
        seen = len(diagnostics)
        assert spin_until(probe, lambda: newest_status(diagnostics[seen:], '/sim_bridge') and
                          newest_status(diagnostics[seen:], '/policy'), timeout=5)
        bridge = newest_status(diagnostics[seen:], '/sim_bridge')
        policy = newest_status(diagnostics[seen:], '/policy')
        # The same publisher throughout: paired once, nothing refused on either side.
        assert bridge['action_sender'].startswith('/policy') and bridge['foreign'] == '0', bridge
        assert policy['lifecycle'] == 'active' and policy['foreign'] == '0', policy
    assert ros_processes.log_text('lc-sim_bridge').count('paired with') == 1


def test_a_container_policy_on_autostart_false_holds_the_loop_until_activated(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """One process, one executor (the container): the policy's lifecycle services answer.

    sim_bridge waits for its peers (the default), so no step goes out until the policy,
    configured and activated by service, publishes actions; then they are applied.
    """
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState
    from zeus_msgs.msg import StepFeedback

    from sim_bridge.actions import ActionStatus
    from zeus_ros.nodes.topics import step_qos

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    ros_processes.start('lc-container', container({
        'sim_bridge': (f'task:={TASK}',),
        'context_estimator': (f'checkpoint:={checkpoint}',),
        'policy': (f'checkpoint:={checkpoint}', 'autostart:=false')}))
    status: dict[int, int] = {}
    with driver_node(ros_processes.domain_id) as probe:
        probe.create_subscription(StepFeedback, 'zeus/step', lambda m: status.__setitem__(
            m.step, m.action_status), step_qos(100))
        get = probe.create_client(GetState, '/policy/get_state')
        change = probe.create_client(ChangeState, '/policy/change_state')
        assert get.wait_for_service(timeout_sec=60) and change.wait_for_service(timeout_sec=10), \
            ros_processes.log_text('lc-container')[-2000:]
        assert _call(probe, get, GetState.Request()).current_state.label == 'unconfigured'
        spin_until(probe, lambda: bool(status), timeout=2.0)
        assert not status, 'sim_bridge stepped with no policy acting'
        for transition_id in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
            answer = _call(probe, change, ChangeState.Request(
                transition=Transition(id=transition_id)))
            assert answer.success, ros_processes.log_text('lc-container')[-2000:]
        assert _call(probe, get, GetState.Request()).current_state.label == 'active'
        assert spin_until(probe, lambda: len([s for s in status.values() if s in (
            ActionStatus.OK, ActionStatus.CLIPPED)]) >= 20, timeout=60), \
            ros_processes.log_text('lc-container')[-2000:]


def test_a_failed_configure_leaves_the_node_unconfigured_and_fixable(tmp_path: Path) -> None:
    """In process: a missing checkpoint fails configure, the right one then configures.

    The failure is the transition's FAILURE, not an exception; operator services refuse while
    the node is unconfigured; cleanup lets go of the checkpoint and the subscriptions.
    """
    from rclpy.lifecycle import TransitionCallbackReturn
    from rclpy.parameter import Parameter

    from zeus_ros.nodes.policy_node import PolicyNode

    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    with ros_context(fresh_domain_id()) as context:
        policy = PolicyNode(context=context, cli_args=[
            '--ros-args', '-p', f'checkpoint:={tmp_path / "missing.pt"}',
            '-p', 'autostart:=false'])
        try:
            assert policy.lifecycle_state() == 'unconfigured'
            with pytest.raises(ValueError, match='unconfigured'):
                policy._freeze_context(True)
            assert policy.trigger_configure() == TransitionCallbackReturn.FAILURE
            assert policy.lifecycle_state() == 'unconfigured' and policy.agent is None
            assert policy.set_parameters([Parameter('checkpoint', value=str(checkpoint))])[
                0].successful
            assert policy.trigger_configure() == TransitionCallbackReturn.SUCCESS
            assert policy.lifecycle_state() == 'inactive' and policy.agent is not None
            assert policy.trigger_activate() == TransitionCallbackReturn.SUCCESS
            assert policy.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
            assert policy.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
            assert policy.agent is None and policy.inputs is None
        finally:
            policy.destroy_node()
