"""zeus launch's restart policy (system/respawn.py): limits, window, back-off, where it is set.

The restarts themselves run with real processes in test/faults/test_fault_logging.py.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from zeus_ros.cli import launch
from zeus_ros.system.respawn import (
    DEFAULT_POLICIES,
    RespawnPolicy,
    RespawnState,
    parse_cli,
    policies_from_params,
)

NODES = ['sim_bridge', 'context_estimator', 'policy', 'recorder']


def test_restarts_back_off_doubling_and_stop_past_the_limit_in_the_window() -> None:
    state = RespawnState(RespawnPolicy(limit=3, window_s=60.0, backoff_s=1.0))
    assert [state.next_delay(t) for t in (0.0, 1.0, 2.0)] == [1.0, 2.0, 4.0]
    assert state.next_delay(3.0) is None  # a 4th death within 60 s: given up
    assert state.next_delay(61.5) == 2.0  # two deaths left the window: the second restart


def test_defaults_restart_estimator_policy_recorder_never_the_bridges() -> None:
    assert {n for n, p in DEFAULT_POLICIES.items() if p.limit} == {
        'context_estimator', 'policy', 'recorder'}
    assert RespawnPolicy().text() == 'never restarted'


def test_params_file_section_and_cli_override_in_that_order() -> None:
    params = {'/**/zeus_launch': {'ros__parameters': {'respawn': {
        'policy': {'limit': 5, 'backoff_s': 0.5}, 'sim_bridge': {'limit': 1}}}}}
    policies = policies_from_params(params, NODES)
    assert policies['policy'] == RespawnPolicy(5, 60.0, 0.5)
    assert policies['sim_bridge'].limit == 1
    policies = parse_cli(['policy=0', 'recorder=2/10/0.25'], NODES, policies)
    assert policies['policy'].limit == 0
    assert policies['recorder'] == RespawnPolicy(2, 10.0, 0.25)


@pytest.mark.parametrize(('params', 'message'), [
    ({'respawn': {'plicy': {'limit': 1}}}, 'respawn.plicy: no such node'),
    ({'respawn': {'policy': {'limit': -1}}}, 'limit must be an integer >= 0'),
    ({'respawn': {'policy': {'limt': 1}}}, "unexpected keyword argument 'limt'"),
    ({'respwn': {}}, "unknown setting(s) ['respwn']"),
])
def test_a_bad_params_section_is_named(params: dict, message: str) -> None:
    with pytest.raises(ValueError, match='zeus_launch') as info:
        policies_from_params({'/**/zeus_launch': {'ros__parameters': params}}, NODES)
    assert message in str(info.value)


@pytest.mark.parametrize('value', ['policy', 'policy=', 'nobody=1', 'policy=x', 'policy=1/2/3/4',
                                   'policy=1/-5'])
def test_a_bad_respawn_flag_is_one_line_exit_2(value: str, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert launch.main(['--respawn', value, '--timeout', '1', '--no-progress']) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f'zeus launch: --respawn {value}:') and len(err.splitlines()) == 1, err


def _group(tmp_path: Path, **argv: str) -> list[launch.NodeProcess]:
    """Stand-in nodes: plain processes running the given Python code (no ROS needed here)."""
    import sys

    return [launch.NodeProcess(name, [sys.executable, '-c', code]) for name, code in
            argv.items()]


@pytest.mark.slow  # stand-in processes, a few seconds
def test_a_crashing_policy_is_restarted_up_to_its_limit_then_the_group_stops(
        tmp_path: Path) -> None:
    import os
    import sys

    nodes = _group(tmp_path, sim_bridge='import time; time.sleep(30)',
                   policy='import sys; sys.exit(1)')
    supervisor = launch.Supervisor(nodes, dict(os.environ), out=sys.stdout, policies={
        'policy': RespawnPolicy(limit=2, window_s=60.0, backoff_s=0.1)})
    supervisor.start()
    try:
        assert supervisor.wait(timeout=20) == ('policy', 1)
    finally:
        supervisor.stop(grace=2)
    assert len(supervisor.restarts) == 2


@pytest.mark.slow  # stand-in processes, a few seconds
def test_a_restarted_recorder_that_refuses_to_start_does_not_stop_the_loop(
        tmp_path: Path) -> None:
    """First a crash (exit 1: restarted), then exit 2 at the restart: given up, loop runs on."""
    import os
    import sys

    marker = tmp_path / 'crashed_once'
    nodes = _group(tmp_path, sim_bridge='import time; time.sleep(30)', recorder=(
        f'import pathlib, sys; m = pathlib.Path({str(marker)!r})\n'
        'if m.exists(): sys.exit(2)\nm.touch(); sys.exit(1)'))
    supervisor = launch.Supervisor(nodes, dict(os.environ), out=sys.stdout)
    supervisor.start()
    try:
        assert supervisor.wait(timeout=3) == (None, 0)  # the time limit, not a node's exit
    finally:
        supervisor.stop(grace=2)
    assert [n.name for n in supervisor.nodes] == ['sim_bridge']
    assert 'refused to restart' in supervisor.gaps[-1]
