"""`ros2 launch zeus_ros zeus.launch.py` as launch_ros runs it (issue 48, items 1 and 2).

launch_ros hands every node its parameter dict as a temporary params file written with
`yaml.dump` (Node._create_params_file_from_dict, after normalize_parameter_dict and
evaluate_parameter_dict): every list comes out tagged `!!python/tuple`. rcl reads such a file;
the nodes' own pre-check refused it, so `ros2 launch` stopped at once. These tests write the
launch file's own dicts exactly that way and start the nodes on them; they check the launch
description (nodes, parameters, respawn, exit handling) with launch stubbed, and, where the
real launch and launch_ros are importable, run the launch file under a LaunchService.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
import contextlib
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any

import pytest
import yaml

from launch_stubs import launch_actions
from ros_harness import (
    REPO,
    ProcessGroup,
    child_pids,
    driver_node,
    fresh_domain_id,
    ros_environment,
    spin_until,
    stop_launch,
)

pytestmark = pytest.mark.ros


# --- what launch_ros does with a parameter dict --------------------------------------------

def launch_ros_values(params: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """A parameter dict as launch_ros evaluates it (jazzy launch_ros/utilities/*_parameters.py).

    Nested dicts flatten to dotted names; a string goes through yaml.dump then yaml.safe_load;
    a list becomes a tuple (all ints: ints, ints and floats: floats, else each item through
    yaml.dump and yaml.safe_load).
    """
    values: dict[str, Any] = {}
    for key, value in params.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            values.update(launch_ros_values(value, f'{name}.'))
        elif isinstance(value, str):
            values[name] = yaml.safe_load(yaml.dump(value))
        elif isinstance(value, list | tuple):
            kinds = {type(item) for item in value}
            if kinds == {int}:
                values[name] = tuple(int(item) for item in value)
            elif kinds in ({float}, {int, float}):
                values[name] = tuple(float(item) for item in value)
            elif kinds == {bool}:
                values[name] = tuple(value)
            else:
                values[name] = tuple(yaml.safe_load(yaml.dump(item)) for item in value)
        else:
            values[name] = value
    return values


def launch_ros_params_file(node: Any, folder: Path) -> Path:
    """The file launch_ros writes for the Node action's dict: yaml.dump, block style.

    Keyed by the full node name when name and namespace are given, else `/**`.
    """
    kwargs = node.kwargs
    namespace = kwargs.get('namespace')
    key = f'{namespace}/{kwargs["name"]}' if namespace else '/**'
    [params] = [p for p in kwargs['parameters'] if isinstance(p, Mapping)]
    path = folder / f'launch_params_{kwargs["name"]}'
    with path.open('w') as handle:
        yaml.dump({key: {'ros__parameters': launch_ros_values(params)}}, handle,
                  default_flow_style=False)
    return path


def launch_ros_args(node: Any, folder: Path) -> list[str]:
    """The `--ros-args` launch_ros gives the Node action: name, namespace, files, remaps."""
    kwargs = node.kwargs
    args = ['--ros-args', '-r', f'__node:={kwargs["name"]}']
    if kwargs.get('namespace'):
        args += ['-r', f'__ns:={kwargs["namespace"]}']
    for params in kwargs['parameters']:
        path = launch_ros_params_file(node, folder) if isinstance(params, Mapping) else params
        args += ['--params-file', str(path)]
    for source, target in kwargs.get('remappings') or []:
        args += ['-r', f'{source}:={target}']
    return [*args, *kwargs.get('ros_arguments', [])]


def _nodes(actions: list[Any]) -> list[Any]:
    return [action for action in actions if type(action).__name__ == 'Node']


# --- item 1: the files launch_ros writes are accepted -----------------------------------------

def test_python_tags_read_as_rcl_reads_them(tmp_path: Path) -> None:
    """`!!python/tuple` (launch_ros's lists) reads as a list; a tag never builds an object.

    The pre-check still refuses, in one line, what rcl refuses.
    """
    from zeus_ros.nodes.spin import params_file_errors
    from zeus_ros.yaml_text import load_yaml_text, safe_load_params

    text = yaml.dump({'/**': {'ros__parameters': {'observers': ('policy', 'recorder'),
                                                  'values': (0.5, -0.25), 'n': 3}}},
                     default_flow_style=False)
    assert '!!python/tuple' in text
    with pytest.raises(yaml.constructor.ConstructorError):
        yaml.safe_load(text)  # what the nodes used to read it with
    expected = {'/**': {'ros__parameters': {'observers': ['policy', 'recorder'],
                                            'values': [0.5, -0.25], 'n': 3}}}
    assert safe_load_params(text) == expected
    tagged = tmp_path / 'tagged.yaml'
    tagged.write_text(text)
    assert load_yaml_text(tagged) == expected
    assert params_file_errors(['--ros-args', '--params-file', str(tagged)]) == []
    # no Python object is made: an apply tag is read as the list it tags, nothing runs
    assert safe_load_params("a: !!python/object/apply:os.getcwd []\nb: !!python/str 'x'\n") == \
        {'a': [], 'b': 'x'}
    for content, error in (('a: [unclosed\n', 'not valid YAML'),
                           ('- 1\n', 'expected a mapping of node names'),
                           ('policy:\n  checkpoint: x.pt\n', 'needs a ros__parameters')):
        tagged.write_text(content)
        [line] = params_file_errors(['--params-file', str(tagged)])
        assert error in line and '\n' not in line, line


LAUNCHES = [
    {},
    {'record': 'true'},
    {'continual': 'true'},
    {'namespace': 'r1', 'use_sim_time': 'true', 'clock': 'namespace', 'record': 'true'},
    {'obs': 'pixels'},
    {'task': 'Cheetah-Motor-v0'},
]


@pytest.mark.parametrize('arguments', LAUNCHES, ids=lambda a: ','.join(
    f'{k}:={v}' for k, v in a.items()) or 'default')
def test_every_node_accepts_the_files_launch_ros_writes(arguments: dict[str, str],
                                                        tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """Each Node of the launch: its dict through yaml.dump passes the pre-check and rcl.

    rcl (an rclpy node given the same --ros-args) reads every value the launch file set.
    """
    import rclpy
    from rclpy.context import Context

    from zeus_ros.nodes.spin import params_file_errors
    from zeus_ros.system import launch_defaults as d

    nodes = _nodes(launch_actions(monkeypatch, **arguments))
    assert nodes
    tagged = 0
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    for node in nodes:
        args = launch_ros_args(node, tmp_path)
        assert params_file_errors(args) == [], node.kwargs['name']
        written = launch_ros_params_file(node, tmp_path)
        tagged += '!!python/tuple' in written.read_text()
        d.read_params(written)  # the launchers' reader takes it too
        context = Context()
        rclpy.init(args=['zeus', *args], context=context, domain_id=fresh_domain_id())
        try:
            probe = rclpy.create_node(node.kwargs['name'], context=context,
                                      automatically_declare_parameters_from_overrides=True)
            try:
                [params] = [p for p in node.kwargs['parameters'] if isinstance(p, Mapping)]
                for name, value in launch_ros_values(params).items():
                    read = probe.get_parameter(name).value
                    assert (list(read) if isinstance(value, tuple) else read) == \
                        (list(value) if isinstance(value, tuple) else value), name
            finally:
                probe.destroy_node()
        finally:
            rclpy.try_shutdown(context=context)
    assert tagged, 'no list parameter: the files are not what broke the launch'


def test_the_nodes_start_and_step_on_launch_ros_params_files(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        ros_processes: ProcessGroup) -> None:
    """record:=true as launch_ros starts it: all four nodes come up and the loop steps.

    (Before: sim_bridge and the recorder exited 2 at once on the tagged files.)
    """
    from zeus_msgs.msg import StepFeedback

    from zeus_ros.nodes.topics import step_qos
    from zeus_ros.system import launch_defaults as d

    monkeypatch.chdir(tmp_path)  # the recorder's ./bags
    actions = launch_actions(monkeypatch, record='true')
    started = {}
    for node in _nodes(actions):
        name = node.kwargs['name']
        argv = [sys.executable, '-m', d.NODES[name], *launch_ros_args(node, tmp_path)]
        started[name] = ros_processes.start(f'launch_ros-{name}', argv,
                                            node.kwargs['additional_env'])
    assert list(started) == ['sim_bridge', 'context_estimator', 'policy', 'recorder']
    seen: list[int] = []
    with driver_node(ros_processes.domain_id, name='bystander') as bystander:
        bystander.create_subscription(StepFeedback, '/zeus/step',
                                      lambda m: seen.append(m.step), step_qos(100))
        stepped = spin_until(bystander, lambda: len(seen) >= 20 or any(
            p.poll() is not None for p in started.values()), timeout=150)
    logs = {name: ros_processes.log_text(f'launch_ros-{name}') for name in started}
    exited = {name: p.poll() for name, p in started.items() if p.poll() is not None}
    assert not exited, f'exited: {exited}\n' + '\n'.join(
        f'[{name}] {log[-1500:]}' for name, log in logs.items() if name in exited)
    assert stepped and seen[0] == 0, (seen[:5], logs['sim_bridge'][-2000:])
    assert 'recording' in logs['recorder'], logs['recorder'][-2000:]
    for name, log in logs.items():
        assert 'error: --params-file' not in log, (name, log[-2000:])


# --- the launch description: nodes, parameters, respawn, exits --------------------------------

def test_the_description_starts_the_plan_with_its_respawn_policy(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Nodes, parameters and launch_ros respawn settings come from the plan and the params file.

    The defaults are `zeus launch`'s (estimator, policy, recorder restarted, the bridges never);
    the params file's /**/zeus_launch respawn: section changes them; every process has an exit
    handler; continual's recorder (a set output) and trainer are not restarted.
    """
    from zeus_ros.system import launch_defaults as d

    actions = launch_actions(monkeypatch, record='true')
    nodes = {n.kwargs['name']: n.kwargs for n in _nodes(actions)}
    plan = d.plan(record=True)
    assert list(nodes) == [n.name for n in plan.nodes]
    for planned in plan.nodes:
        assert nodes[planned.name]['parameters'] == [str(plan.params_file), planned.parameters]
        assert nodes[planned.name]['executable'] == f'{planned.name}_node'
    assert nodes['sim_bridge']['respawn'] is False
    for name, delay in (('context_estimator', 1.0), ('policy', 1.0), ('recorder', 0.5)):
        assert (nodes[name]['respawn'], nodes[name]['respawn_delay'],
                nodes[name]['respawn_max_retries']) == (True, delay, 3), name
    handlers = [a for a in actions if type(a).__name__ == 'RegisterEventHandler']
    targets = [h.args[0].kwargs['target_action'] for h in handlers]
    assert targets == _nodes(actions)

    params = tmp_path / 'params.yaml'
    params.write_text(plan.params_file.read_text().replace(
        '      policy: {limit: 3, window_s: 60.0, backoff_s: 1.0}',
        '      policy: {limit: 1, backoff_s: 2.5}\n      sim_bridge: {limit: 2}').replace(
        'checkpoints/cheetah_bias_v0/zeus.pt', str(nodes['policy']['parameters'][1]
                                                   ['checkpoint'])))
    nodes = {n.kwargs['name']: n.kwargs for n in _nodes(launch_actions(
        monkeypatch, params_file=str(params)))}
    assert (nodes['policy']['respawn_delay'], nodes['policy']['respawn_max_retries']) == (2.5, 1)
    assert (nodes['sim_bridge']['respawn'], nodes['sim_bridge']['respawn_max_retries']) == \
        (True, 2)

    actions = launch_actions(monkeypatch, continual='true')
    nodes = {n.kwargs['name']: n.kwargs for n in _nodes(actions)}
    assert nodes['recorder']['respawn'] is False  # its output is set: a restart would refuse it
    trainer = nodes[d.TRAINER]  # a node executable like the others, never restarted
    assert (trainer['executable'], trainer['respawn']) == ('continual_trainer_node', False)
    assert not [a for a in actions if type(a).__name__ == 'ExecuteProcess']
    assert len([a for a in actions if type(a).__name__ == 'RegisterEventHandler']) == 5

    actions = launch_actions(monkeypatch, single_process='true', record='true')
    container, recorder = _nodes(actions)
    assert container.kwargs['executable'] == d.CONTAINER_EXECUTABLE
    assert container.kwargs['respawn'] is False and recorder.kwargs['respawn'] is True


class _Exited:
    """A ProcessExited event's stand-in: its exit status."""

    def __init__(self, returncode: int) -> None:
        self.returncode = returncode


class _Context:
    """A LaunchContext's stand-in: whether the launch is shutting down."""

    def __init__(self, is_shutdown: bool = False) -> None:
        self.is_shutdown = is_shutdown


def test_a_node_dead_for_good_fails_the_launch(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each exit handler says what an exit means, as `zeus launch` does.

    A policy is restarted 3 times (logged), its 4th death fails the launch (NodeDiedError:
    launch returns 1); sim_bridge (never restarted) fails it at its first crash and stops it
    cleanly on exit 0; exit 2 fails at once; the recorder's end never stops the loop; exits
    during the launch's own shutdown are not judged.
    """
    actions = launch_actions(monkeypatch, record='true')
    handlers = {h.args[0].kwargs['target_action'].kwargs['name']: h.args[0].kwargs['on_exit']
                for h in actions if type(h).__name__ == 'RegisterEventHandler'}
    for restart in (1, 2, 3):
        [log] = handlers['policy'](_Exited(-9), _Context())
        assert type(log).__name__ == 'LogInfo'
        assert f'restarting it in 1 s (restart {restart} of 3' in log.kwargs['msg']
    with pytest.raises(RuntimeError, match='policy exited with code -9 after 3') as died:
        handlers['policy'](_Exited(-9), _Context())
    assert type(died.value).__name__ == 'NodeDiedError'
    assert handlers['context_estimator'](_Exited(1), _Context(is_shutdown=True)) is None
    with pytest.raises(RuntimeError, match='refused its parameters'):
        handlers['context_estimator'](_Exited(2), _Context())
    with pytest.raises(RuntimeError, match='never restarted'):
        handlers['sim_bridge'](_Exited(-11), _Context())
    # a fresh launch: sim_bridge's first exit is a clean one
    fresh = {h.args[0].kwargs['target_action'].kwargs['name']: h.args[0].kwargs['on_exit']
             for h in launch_actions(monkeypatch) if type(h).__name__ == 'RegisterEventHandler'}
    [shutdown] = fresh['sim_bridge'](_Exited(0), _Context())
    assert type(shutdown).__name__ == 'EmitEvent'
    assert shutdown.kwargs['event'].kwargs['reason'] == 'sim_bridge exited with code 0: ' \
        'the launch stops'
    for _ in range(3):
        handlers['recorder'](_Exited(1), _Context())
    [log] = handlers['recorder'](_Exited(1), _Context())
    assert 'the rest of the run is not recorded' in log.kwargs['msg']


# --- the real launch, where launch and launch_ros are importable -------------------------------

_RUN_LAUNCH = """
import sys
from launch import LaunchDescription, LaunchService
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource
service = LaunchService(argv=sys.argv[2:])
service.include_launch_description(LaunchDescription([IncludeLaunchDescription(
    PythonLaunchDescriptionSource(sys.argv[1]),
    launch_arguments=[arg.split(':=', 1) for arg in sys.argv[2:]])]))
sys.exit(service.run())
"""
"""What `ros2 launch zeus_ros zeus.launch.py ARGS` does (ros2launch.api.launch_a_launch_file)."""


@contextlib.contextmanager
def _real_launch(*arguments: str) -> Iterator[tuple[subprocess.Popen[str], list[str]]]:
    """The installed launch file under a real LaunchService; its output lines so far."""
    import threading

    from zeus_ros.system import launch_defaults as d

    launch = subprocess.Popen(
        [sys.executable, '-c', _RUN_LAUNCH, str(d.share_dir() / 'launch' / 'zeus.launch.py'),
         *arguments], cwd=REPO, env=ros_environment(fresh_domain_id()),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    lines: list[str] = []
    output = launch.stdout
    assert output is not None
    reader = threading.Thread(target=lambda: lines.extend(iter(output.readline, '')),
                              daemon=True)
    reader.start()
    try:
        yield launch, lines
    finally:
        stop_launch(launch)
        reader.join(timeout=10)


def _node_pid(launch: subprocess.Popen[str], name: str) -> int | None:
    """The pid of the launch's child running node `name` (launch_ros: `-r __node:=name`)."""
    for pid, argv in child_pids(launch.pid).items():
        if f'__node:={name}'.encode() in argv:
            return pid
    return None


def _wait(predicate: Any, timeout: float, what: str, lines: list[str]) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f'{what} within {timeout} s:\n' + ''.join(lines[-60:]))
        time.sleep(0.2)


def test_ros2_launch_restarts_a_killed_node_and_fails_when_one_died_for_good() -> None:
    """The real launch (when importable): the loop steps on launch_ros's own params files.

    A killed policy is restarted (its respawn policy); a killed sim_bridge (never restarted)
    ends the launch with exit status 1, naming it.
    """
    pytest.importorskip('launch_ros', reason='launch_ros is not in this environment (not on '
                        'PyPI): the stubbed tests above cover the description')
    with _real_launch('log_level:=info') as (launch, lines):
        _wait(lambda: any('paired with /policy' in line for line in lines) or
              launch.poll() is not None, 240, 'the loop did not start', lines)
        assert launch.poll() is None, ''.join(lines[-60:])
        assert not any('error: --params-file' in line for line in lines), ''.join(lines)
        first = _node_pid(launch, 'policy')
        assert first is not None
        os.kill(first, signal.SIGKILL)
        _wait(lambda: any('policy exited with code -9; restarting it in 1 s' in line
                          for line in lines), 30, 'no restart was named', lines)
        _wait(lambda: _node_pid(launch, 'policy') not in (None, first), 30,
              'the policy was not restarted', lines)
        bridge = _node_pid(launch, 'sim_bridge')
        assert bridge is not None
        os.kill(bridge, signal.SIGKILL)
        assert launch.wait(timeout=90) == 1, ''.join(lines[-60:])
    assert any('sim_bridge exited with code -9 (never restarted' in line for line in lines), \
        ''.join(lines[-60:])
