"""The executor every node process spins on ($ZEUS_EXECUTOR, nodes/spin.make_executor).

Real node processes, one fresh domain per test, loopback only, always cleaned up.
"""

from __future__ import annotations

import signal
import sys
from typing import Any

from executor_probe import SAYS
import pytest

from live_fixtures import TASK
from ros_harness import (
    REPO,
    ProcessGroup,
    driver_node,
    fresh_domain_id,
    require_ros,
    spin_until,
)

pytestmark = pytest.mark.ros

CLASS_NAMES = {'single': 'SingleThreadedExecutor', 'events': 'EventsExecutor'}
"""$ZEUS_EXECUTOR -> the class a node's `executor` is then."""


def call(node: Any, future: Any, timeout: float = 20.0) -> Any:
    """Spin until a parameter-service future is done; its result."""
    assert spin_until(node, future.done, timeout), 'no answer from the parameter service'
    return future.result()


def test_the_executor_is_chosen_by_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    """Unset or empty: the default (the first of EXECUTORS); a wrong name: one clear error."""
    from zeus_ros.nodes.spin import EXECUTOR_ENV, EXECUTORS, executor_kind

    monkeypatch.delenv(EXECUTOR_ENV, raising=False)
    assert executor_kind() == EXECUTORS[0]
    monkeypatch.setenv(EXECUTOR_ENV, '')
    assert executor_kind() == EXECUTORS[0]
    for kind in EXECUTORS:
        monkeypatch.setenv(EXECUTOR_ENV, f' {kind.upper()} ')
        assert executor_kind() == kind
    monkeypatch.setenv(EXECUTOR_ENV, 'multi')
    with pytest.raises(ValueError, match=r"ZEUS_EXECUTOR='multi': unknown executor; choose "
                                         r'from events, single'):
        executor_kind()


def test_a_guard_condition_keeps_the_single_threaded_executor() -> None:
    """A node with a guard condition keeps the single-threaded executor.

    The events executor cannot serve guard conditions, also when it was asked for.
    """
    require_ros()
    from rclpy.executors import SingleThreadedExecutor

    from zeus_ros.nodes.spin import make_executor

    with driver_node(fresh_domain_id(), 'guarded') as node:
        node.create_guard_condition(lambda: None)
        executor = make_executor([node], 'events', context=node.context)
        assert isinstance(executor, SingleThreadedExecutor)
        assert node.executor is executor
        executor.shutdown()


@pytest.mark.parametrize('kind', list(CLASS_NAMES))
def test_a_node_spins_on_the_chosen_executor_answers_parameters_and_stops_on_sigint(
        ros_processes: ProcessGroup, kind: str) -> None:
    """sim_bridge as its process runs it, under each executor: the one it reports is chosen.

    `ros2 param`'s services answer (a value set live is read back, a bad one refused with its
    reason); one SIGINT ends it with exit code 0, no traceback, no FATAL.
    """
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    name = f'executor-{kind}'
    process = ros_processes.start(
        name, [sys.executable, str(REPO / 'test' / 'executor_probe.py'), '--ros-args',
               '-p', f'task:={TASK}'], extra_env={'ZEUS_EXECUTOR': kind})
    ros_processes.wait_for_log(name, SAYS, timeout=60)
    assert SAYS + CLASS_NAMES[kind] in ros_processes.log_text(name)
    with driver_node(ros_processes.domain_id) as probe:
        params = AsyncParameterClient(probe, 'sim_bridge')
        assert params.wait_for_services(30)
        results = call(probe, params.set_parameters([
            Parameter('max_steps', value=7), Parameter('max_steps', value=-1)])).results
        assert results[0].successful and not results[1].successful and results[1].reason
        values = call(probe, params.get_parameters(['max_steps'])).values
        assert values[0].integer_value == 7
    assert process.poll() is None, ros_processes.log_text(name)[-2000:]
    code = ros_processes.stop(process, sig=signal.SIGINT, timeout=10)
    log = ros_processes.log_text(name)
    assert code == 0, log[-2000:]
    assert 'Traceback' not in log and 'FATAL' not in log, log[-2000:]


def test_an_unknown_executor_stops_the_node_at_start(ros_processes: ProcessGroup) -> None:
    """A wrong $ZEUS_EXECUTOR: one line naming it and the choices, exit code 2."""
    process = ros_processes.start(
        'executor-bad', [sys.executable, '-m', 'zeus_ros.nodes.sim_bridge_node', '--ros-args',
                         '-p', f'task:={TASK}'], extra_env={'ZEUS_EXECUTOR': 'threads'})
    assert process.wait(timeout=60) == 2
    log = ros_processes.log_text('executor-bad')
    assert "error: ZEUS_EXECUTOR='threads': unknown executor; choose from events, single" in log
    assert 'Traceback' not in log, log
