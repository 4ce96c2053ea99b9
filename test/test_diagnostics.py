"""/diagnostics as diagnostic_updater users expect: hardware_id, STALE peers, whole messages.

And the analyzer file for diagnostic_aggregator (params/diagnostic_aggregator.yaml): it names
every node kind, and its rules match the status names the nodes build (not run here:
diagnostic_aggregator is not on PyPI).
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
import os
import re
import signal
import socket
import time
from typing import Any

import pytest
import yaml

from live_fixtures import TASK
from ros_harness import REPO, ProcessGroup, fresh_domain_id, python_module, ros_context

pytestmark = pytest.mark.ros

ANALYZERS = REPO / 'params' / 'diagnostic_aggregator.yaml'
ADVICE = ('3 publishers on /clock: /a/sim_bridge (gid 01), /b/sim_bridge (gid 02) besides this '
          'node; simulation time jumps between them (give each system its own clock: '
          'clock:=namespace, docs/security.md); ' + 'and more advice ' * 20).strip()


def _level(status: Any) -> int:
    """A status's level (or a level constant) as an int: rclpy gives one byte."""
    level = getattr(status, 'level', status)
    return int.from_bytes(level, 'little') if isinstance(level, bytes) else int(level)


def _heard(pairing: Any, node: str, ago: float = 0.0) -> None:
    """Make `pairing` paired with `node` and its last message `ago` seconds old."""
    from zeus_ros.nodes.senders import Sender

    gid = bytes(range(16))
    pairing.paired = Sender(gid, node)
    assert pairing.accepts(gid)
    pairing.last_message = time.monotonic() - ago


def test_a_status_names_its_system_and_device_keeps_its_advice_and_a_silent_peer_is_stale(
) -> None:
    """hardware_id, the whole message, a peer's silence: in one rclpy process.

    hardware_id is `<ns>/<device>`, fixed for life; a 400-character message arrives whole; a
    peer heard 1 s ago is OK, 4 s ago STALE naming it; heard again, OK.
    """
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    import rclpy

    from zeus_ros.nodes.diagnostics import (
        PEER_SILENT_S,
        diagnostics_message,
        peer_statuses,
        set_device,
    )
    from zeus_ros.nodes.senders import SenderPairing

    from ros_harness import spin_until

    with ros_context(fresh_domain_id()) as context:
        bridge = rclpy.create_node('sim_bridge', namespace='/r1', context=context)
        policy = rclpy.create_node('policy', context=context)
        try:
            set_device(bridge, f'sim:{TASK}')
            array = diagnostics_message(bridge, 'step loop', {'steps': 3}, [], [ADVICE])
            (status,) = array.status
            assert status.hardware_id == f'/r1/sim:{TASK}'
            assert status.message == ADVICE and len(ADVICE) > 300
            assert _level(status) == _level(DiagnosticStatus.ERROR)
            set_device(bridge, 'sim:other')  # too late: fixed for the node's life
            assert diagnostics_message(bridge, 'x', {}).status[0].hardware_id == f'/r1/sim:{TASK}'
            assert diagnostics_message(policy, 'actions', {}).status[0].hardware_id == \
                f'/host:{socket.gethostname()}'

            received: list[Any] = []
            probe = rclpy.create_node('probe', context=context)
            probe.create_subscription(DiagnosticArray, '/diagnostics', received.append, 10)
            publisher = bridge.create_publisher(DiagnosticArray, '/diagnostics', 10)
            assert spin_until(probe, lambda: publisher.get_subscription_count() > 0, 10)
            publisher.publish(array)
            assert spin_until(probe, lambda: bool(received), 10)
            assert received[0].status[0].message == ADVICE, 'cut on its way'
            probe.destroy_node()

            actions = SenderPairing(bridge, '/r1/zeus/action', what='actions')
            assert peer_statuses(bridge) == [], 'a peer never heard is not reported'
            _heard(actions, '/r1/policy', ago=1.0)
            (peer,) = diagnostics_message(bridge, 'step loop', {}).status[1:]
            assert peer.name == '/r1/sim_bridge: peer /r1/policy'
            assert _level(peer) == _level(DiagnosticStatus.OK)
            assert peer.hardware_id == f'/r1/sim:{TASK}'
            actions.last_message = time.monotonic() - PEER_SILENT_S - 1.0
            (peer,) = peer_statuses(bridge)
            assert _level(peer) == _level(DiagnosticStatus.STALE)
            assert peer.message.startswith('no actions from /r1/policy on /r1/zeus/action for 4')
            assert diagnostics_message(bridge, 'x', {}, peers=False).status[1:] == []
            _heard(actions, '/r1/policy')
            assert _level(peer_statuses(bridge)[0]) == _level(DiagnosticStatus.OK)
        finally:
            bridge.destroy_node()
            policy.destroy_node()


def _analyzers() -> Iterator[tuple[str, str, dict[str, Any]]]:
    """(key, full path, parameters) of every GenericAnalyzer, AnalyzerGroups walked."""
    root = yaml.safe_load(ANALYZERS.read_text())['analyzers']['ros__parameters']

    def walk(base: str, tree: dict[str, Any]) -> Iterator[tuple[str, str, dict[str, Any]]]:
        for key, spec in tree.items():
            if not isinstance(spec, dict):
                continue
            path = f'{base}/{spec["path"]}'
            if spec['type'] == 'diagnostic_aggregator/AnalyzerGroup':
                yield from walk(path, spec['analyzers'])
            else:
                assert spec['type'] == 'diagnostic_aggregator/GenericAnalyzer', key
                yield key, path, spec

    return walk(f'/{root["path"]}', root)


def _matches(spec: dict[str, Any], name: str) -> bool:
    """GenericAnalyzer::match (diagnostic_aggregator, Jazzy)."""
    starts = [*spec.get('startswith', []), *spec.get('find_and_remove_prefix', [])]
    return (any(name.startswith(s) for s in starts)
            or any(c in name for c in spec.get('contains', []))
            or name in spec.get('name', []) or name in spec.get('expected', [])
            or any(re.fullmatch(r, name) for r in spec.get('regex', [])))


def _shown(path: str, spec: dict[str, Any], name: str) -> str:
    """The name under /diagnostics_agg: getOutputName, then removeLeadingNameChaff."""
    shown = f'{path}/{name.replace("/", " ")}'
    for chaff in [*spec.get('find_and_remove_prefix', []), *spec.get('remove_prefix', [])]:
        chaff = chaff.replace('/', ' ')
        slash = shown.rfind('/')
        start = shown[:slash + 1]
        if shown.find(chaff) == slash + 1:
            shown = start + shown[slash + 1 + len(chaff):]
        if shown.find(':', slash) == slash + 1:
            shown = start + shown[slash + 2:]
        while shown.find(' ', slash) == slash + 1:
            shown = start + shown[slash + 2:]
    return shown


def _published_names() -> dict[str, set[str]]:
    """Node kind -> the status names its source passes to diagnostics_message."""
    found: dict[str, set[str]] = {}
    for path in sorted((REPO / 'zeus_ros' / 'nodes').glob('*.py')):
        tree = ast.parse(path.read_text())
        kinds = [call.args[0].value for call in ast.walk(tree) if isinstance(call, ast.Call)
                 and isinstance(call.func, ast.Attribute) and call.func.attr == '__init__'
                 and call.args and isinstance(call.args[0], ast.Constant)]
        names = {call.args[1].value for call in ast.walk(tree) if isinstance(call, ast.Call)
                 and getattr(call.func, 'id', getattr(call.func, 'attr', '')) ==
                 'diagnostics_message' and isinstance(call.args[1], ast.Constant)}
        if names:
            assert len(kinds) == 1, (path, kinds)
            found.setdefault(kinds[0], set()).update(names)
    return found


def test_the_aggregator_file_groups_every_status_the_nodes_build_under_its_node_kind() -> None:
    """Every node kind has its analyzer, and each status of a node lands under it.

    Each status (and peer status) of a node, in the root namespace or another, matches its
    kind's analyzer only; in the root one it is shown without the node's name.
    """
    import rclpy

    from zeus_ros.nodes.diagnostics import diagnostics_message
    from zeus_ros.nodes.senders import SenderPairing
    from zeus_ros.system.launch_defaults import NODES

    published = _published_names()
    assert set(published) == set(NODES), 'a node kind publishes no status, or is unknown'
    assert published['sim_bridge'] == {'step loop'}
    analyzers = list(_analyzers())
    assert {key for key, _, _ in analyzers} == set(NODES)
    with ros_context(fresh_domain_id()) as context:
        for kind, names in published.items():
            for namespace in ('/', '/r1'):
                node = rclpy.create_node(kind, namespace=namespace, context=context)
                try:
                    _heard(SenderPairing(node, '/zeus/step', what='steps'),
                           f'{namespace.rstrip("/")}/sim_bridge')
                    statuses = [s for name in sorted(names)
                                for s in diagnostics_message(node, name, {}).status]
                    for status in statuses:
                        hits = [(key, path, spec) for key, path, spec in analyzers
                                if _matches(spec, status.name)]
                        assert [key for key, _, _ in hits] == [kind], status.name
                        _, path, spec = hits[0]
                        if namespace == '/':
                            what = status.name.split(': ', 1)[1].replace('/', ' ')
                            assert _shown(path, spec, status.name) == f'{path}/{what}'
                finally:
                    node.destroy_node()
    shown = {path for _, path, _ in analyzers}
    assert '/Zeus/Control loop/Simulator' in shown and '/Zeus/Recorder' in shown


def _node(name: str, *params: str) -> list[str]:
    args = [arg for param in params for arg in ('-p', param)]
    return python_module(f'zeus_ros.nodes.{name}_node', '--ros-args', '-r', '__ns:=/r1', *args)


@pytest.mark.ros_quiet  # timing: a silence of seconds is measured
def test_a_stalled_policy_goes_stale_at_the_bridge_and_in_zeus_inspect(
        ros_processes: ProcessGroup, monkeypatch: pytest.MonkeyPatch) -> None:
    """A policy that stops talking is STALE where it is watched; SIGCONT: OK again.

    SIGSTOP the policy of a namespaced system: sim_bridge says STALE naming it, `zeus inspect`
    shows the policy's status STALE once its /diagnostics stopped.
    """
    from diagnostic_msgs.msg import DiagnosticStatus

    from zeus_ros.cli.inspect_topics import Inspector
    from zeus_ros.nodes.diagnostics import PEER_SILENT_S

    policy = ros_processes.start('policy', _node('policy', f'task:={TASK}'))
    ros_processes.start('sim_bridge', _node('sim_bridge', f'task:={TASK}', 'min_observers:=1',
                                            'action_timeout:=0.5'))
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_processes.domain_id))
    inspector = Inspector(namespace='/r1')
    peer, actions = '/r1/sim_bridge: peer /r1/policy', '/r1/policy: actions'

    def until(predicate: Any, timeout: float, what: str) -> float:
        start = time.monotonic()
        while not predicate():
            assert time.monotonic() - start < timeout, (what, inspector.statuses,
                                                        ros_processes.log_text('sim_bridge'))
            inspector.executor.spin_once(timeout_sec=0.05)
        return time.monotonic() - start

    def level(name: str) -> int:
        heard = inspector.statuses.get(name)
        return -1 if heard is None else heard.level

    try:
        until(lambda: level(peer) == 0 and level(actions) == 0, 60, 'a running system')
        assert inspector.statuses['/r1/sim_bridge: step loop'].hardware_id == f'/r1/sim:{TASK}'
        assert inspector.statuses[actions].hardware_id == f'/r1/host:{socket.gethostname()}'
        os.kill(policy.pid, signal.SIGSTOP)
        stale_s = until(lambda: level(peer) == _level(DiagnosticStatus.STALE), 20,
                        'the bridge calling the policy STALE')
        assert '/r1/policy' in inspector.statuses[peer].message
        shown_s = until(lambda: inspector.statuses[actions].state(time.monotonic())
                        .startswith('STALE: no /diagnostics'), 20, 'inspect: STALE')
        until(lambda: inspector.current() is not None, 20, 'a step to view')
        assert f'{actions}: STALE: no /diagnostics for' in inspector.view()
        assert f'{peer}: STALE: no actions from /r1/policy' in inspector.view()
        print(f'\nSTALE at the bridge {stale_s:.1f} s after SIGSTOP (threshold '
              f'{PEER_SILENT_S:g} s), in inspect {stale_s + shown_s:.1f} s')
        os.kill(policy.pid, signal.SIGCONT)
        back_s = until(lambda: level(peer) == 0 and not inspector.statuses[actions]
                       .state(time.monotonic()).startswith('STALE'), 30, 'OK again')
        print(f'OK again {back_s:.1f} s after SIGCONT')
    finally:
        os.kill(policy.pid, signal.SIGCONT)
        inspector.close()
