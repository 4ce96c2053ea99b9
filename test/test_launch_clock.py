"""A namespaced sim-time system runs on its own clock unless told otherwise (issue 48, item 7).

Why: on the one global /clock, a second simulated system in the domain stalls the first and
mixes both clocks in its bag; forgetting `clock:=namespace` did exactly that. Now an unset
clock is <namespace>/clock for a namespaced launch on simulation time, in the plan, in
`zeus launch` and in the launch file's description (launch stubbed: no ros2cli needed);
`clock:=global` keeps the shared /clock as an explicit choice.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from launch_stubs import launch_actions

ALL_NODES = {'sim_bridge', 'context_estimator', 'policy', 'recorder', 'continual_trainer'}


def test_a_namespaced_sim_time_plan_without_a_clock_gets_the_namespace_clock(
        tmp_path: Path) -> None:
    """Every node (container included) is remapped to /r1/clock; global and wall time are not.

    Sim time set in the params file (not the argument) counts as sim time too.
    """
    from zeus_ros.system import launch_defaults as d

    plan = d.plan_from_arguments({'namespace': 'r1', 'use_sim_time': 'true',
                                  'continual': 'true'})
    assert {n.name for n in plan.nodes} == ALL_NODES
    assert plan.remappings == [('/clock', '/r1/clock')]
    for node in plan.nodes:
        args = plan.ros_args(node)
        assert args[args.index('/clock:=/r1/clock') - 1] == '-r', node.name
    contained = d.plan(namespace='r1', use_sim_time=True, single_process=True, record=True)
    assert contained.container_args().count('/clock:=/r1/clock') == len(contained.contained)
    assert d.plan(namespace='/r1/', use_sim_time=True).clock == '/r1/clock'
    assert d.plan(namespace='r1', use_sim_time=True, clock='global').remappings == []
    assert d.plan(namespace='r1', use_sim_time=True, clock='/clock').remappings == []
    assert d.plan(namespace='r1').remappings == [], 'wall time: /clock stays global'
    assert d.plan(use_sim_time=True).remappings == [], 'no namespace: the one system'
    params = tmp_path / 'p.yaml'
    params.write_text(d.default_params_file().read_text()
                      + '/**:\n  ros__parameters:\n    use_sim_time: true\n')
    assert d.plan(namespace='r1', params_file=params, checkpoint=str(
        d.plan().nodes[1].parameters['checkpoint'])).clock == '/r1/clock'


def test_zeus_launch_leaves_the_clock_to_the_plan(monkeypatch: pytest.MonkeyPatch) -> None:
    """`zeus launch --namespace r1 --sim-time` (no --clock) plans /r1/clock for every node."""
    from zeus_ros.cli import launch
    from zeus_ros.system import launch_defaults as d

    planned: list[d.LaunchPlan] = []
    real_plan = d.plan

    def plan(**kwargs: Any) -> d.LaunchPlan:
        planned.append(real_plan(**kwargs))
        raise ValueError('planned')  # stop before anything starts

    monkeypatch.setattr(launch.launch_defaults, 'plan', plan)
    assert launch.main(['--namespace', 'r1', '--sim-time']) == 2
    assert launch.main(['--namespace', 'r1', '--sim-time', '--clock', 'global']) == 2
    assert [p.remappings for p in planned] == [[('/clock', '/r1/clock')], []]


@pytest.mark.parametrize('single_process', ['false', 'true'])
def test_the_launch_description_remaps_every_node_to_the_namespace_clock(
        single_process: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """ros2 launch ... namespace:=r1 use_sim_time:=true: each Node carries the remap."""
    nodes = [a for a in launch_actions(monkeypatch, namespace='r1', use_sim_time='true',
                                       record='true', single_process=single_process)
             if type(a).__name__ == 'Node']
    assert len(nodes) == (2 if single_process == 'true' else 4)
    for node in nodes:
        if node.kwargs['executable'] == 'loop_container':  # each node inside: its --ros-args
            assert node.kwargs['arguments'].count('/clock:=/r1/clock') == 3
        else:
            assert node.kwargs['remappings'] == [('/clock', '/r1/clock')], node.kwargs['name']
    explicit = [a for a in launch_actions(monkeypatch, namespace='r1', use_sim_time='true',
                                          clock='global') if type(a).__name__ == 'Node']
    assert explicit and all(n.kwargs['remappings'] == [] for n in explicit)
