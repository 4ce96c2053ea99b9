"""`zeus launch`: one domain for the group, prefixed logs, everything stops when one node dies."""

from __future__ import annotations

from pathlib import Path
import subprocess
import sys
from typing import Any

import pytest

from launch_stubs import installed_launch_description
from ros_harness import REPO, fresh_domain_id, ros_environment

pytestmark = pytest.mark.ros


def test_a_dying_node_stops_the_group_and_is_named(tmp_path) -> None:
    """A policy refusing its parameters exits 2; launch stops sim_bridge and names the policy.

    (A missing checkpoint no longer gets that far: `zeus launch` refuses it before any start.)
    """
    params = tmp_path / 'params.yaml'
    params.write_text(
        'sim_bridge:\n  ros__parameters:\n    task: Cheetah-Run-v0\n'
        'policy:\n  ros__parameters:\n    task: Cheetah-Run-v0\n    noise: 5.0\n')
    result = subprocess.run(
        [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params', str(params),
         '--nodes', 'sim_bridge,policy', '--timeout', '120'],
        cwd=REPO, env=ros_environment(fresh_domain_id()), capture_output=True, text=True,
        timeout=180, check=False)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "node 'policy' died with exit code 2" in result.stderr
    assert '[policy] error: policy: parameter noise must be <= 0.5' in result.stdout
    assert '[sim_bridge]' in result.stdout


def test_the_group_runs_until_the_time_limit_then_stops_cleanly(tmp_path) -> None:
    """sim_bridge and a random policy run together; the time limit stops both with exit 0."""
    params = tmp_path / 'params.yaml'
    params.write_text(
        'sim_bridge:\n  ros__parameters:\n    task: Cheetah-Run-v0\n    log_every: 50\n'
        'policy:\n  ros__parameters:\n    task: Cheetah-Run-v0\n')
    result = subprocess.run(
        [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params', str(params),
         '--nodes', 'sim_bridge,policy', '--timeout', '12'],
        cwd=REPO, env=ros_environment(fresh_domain_id()), capture_output=True, text=True,
        timeout=120, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert '[sim_bridge]' in result.stdout and 'step 50 ' in result.stdout
    assert 'time limit of 12.0 s reached' in result.stdout


# --- one set of defaults for `ros2 launch zeus_ros zeus.launch.py` and `zeus launch` -------

def test_defaults_are_the_installed_params_and_checkpoint() -> None:
    """No arguments: the installed zeus.yaml, its checkpoint as an absolute installed path."""
    from zeus_ros.system import launch_defaults as d

    plan = d.plan()
    share = d.share_dir()
    assert plan.params_file == share / 'params' / 'zeus.yaml' and plan.params_file.is_file()
    assert [n.name for n in plan.nodes] == ['sim_bridge', 'context_estimator', 'policy']
    nodes = {n.name: n.parameters for n in plan.nodes}
    assert nodes['sim_bridge'] == {'min_observers': 2,
                                   'observers': ['context_estimator', 'policy'],
                                   'action_sender': '/policy'}  # its pairing, by name
    assert nodes['context_estimator']['expected_subscribers'] == 1  # the policy
    assert nodes['policy']['expected_subscribers'] == 1  # sim_bridge
    for name in d.AGENT_NODES:
        checkpoint = Path(nodes[name]['checkpoint'])
        assert checkpoint.is_absolute() and checkpoint.is_file()
        assert str(checkpoint).startswith(str(share)), checkpoint
    assert (plan.namespace, plan.log_level) == ('', 'info')


def test_record_counts_the_recorder_and_arguments_apply_to_every_node(tmp_path: Path) -> None:
    """record:=true adds the recorder, counted in min_observers and expected_subscribers.

    The recorder in turn expects the group's publishers of steps and answers.

    namespace, use_sim_time, checkpoint and log_level reach every node they concern.
    """
    from zeus_ros.system import launch_defaults as d

    ckpt = tmp_path / 'mine.pt'
    ckpt.write_bytes(b'x')
    plan = d.plan_from_arguments({'record': 'true', 'use_sim_time': 'True',
                                  'namespace': '/robot1/', 'checkpoint': str(ckpt),
                                  'log_level': 'debug'})
    nodes = {n.name: n.parameters for n in plan.nodes}
    assert list(nodes) == ['sim_bridge', 'context_estimator', 'policy', 'recorder']
    assert nodes['sim_bridge']['min_observers'] == 3
    # context: policy + recorder; actions: sim_bridge + recorder (so the bag has step 0)
    assert nodes['context_estimator']['expected_subscribers'] == 2
    assert nodes['policy']['expected_subscribers'] == 2
    assert 'expected_subscribers' not in nodes['recorder']
    # and the recorder subscribes to the steps only once it hears steps, context and actions
    assert nodes['recorder']['expected_publishers'] == ['/zeus/step', '/zeus/context',
                                                        '/zeus/action']
    assert all(p['use_sim_time'] is True for p in nodes.values())
    assert nodes['policy']['checkpoint'] == nodes['context_estimator']['checkpoint'] == str(ckpt)
    assert (plan.namespace, plan.log_level) == ('/robot1', 'debug')
    args = plan.ros_args(plan.nodes[2])
    assert args[:2] == ['--params-file', str(plan.params_file)]
    assert args[2:4] == ['-r', '__ns:=/robot1'] and args[-2:] == ['--log-level', 'debug']
    assert f"checkpoint:='{ckpt}'" in args and 'use_sim_time:=true' in args
    assert "expected_publishers:=['/zeus/step','/zeus/context','/zeus/action']" in \
        plan.ros_args(plan.nodes[3])
    # zeus launch's status line subscribes to zeus/step too: sim_bridge waits for the group's
    # nodes by name, so that subscriber cannot stand in for one not subscribed yet
    assert plan.nodes[0].parameters['observers'] == ['context_estimator', 'policy', 'recorder']
    assert "observers:=['context_estimator','policy','recorder']" in \
        plan.ros_args(plan.nodes[0])
    for bad, match in (({'record': 'maybe'}, 'record'), ({'log_level': 'loud'}, 'log_level'),
                       ({'nope': '1'}, 'unknown launch argument')):
        with pytest.raises(ValueError, match=match):
            d.plan_from_arguments(bad)


def test_clock_and_pairing_peers_follow_the_namespace(tmp_path: Path) -> None:
    """clock:=namespace remaps every node's /clock into it; each node names its peers there.

    A peer the params file names is left as the file says; a bad clock is one clear error.
    """
    from zeus_ros.system import launch_defaults as d

    plan = d.plan_from_arguments({'namespace': 'r1', 'use_sim_time': 'true',
                                  'clock': 'namespace', 'record': 'true'})
    nodes = {n.name: n.parameters for n in plan.nodes}
    assert plan.remappings == [('/clock', '/r1/clock')]
    assert all(plan.ros_args(n)[4:6] == ['-r', '/clock:=/r1/clock'] for n in plan.nodes)
    assert nodes['sim_bridge']['action_sender'] == '/r1/policy'
    assert nodes['policy']['step_source'] == nodes['context_estimator']['step_source'] == \
        '/r1/sim_bridge'
    assert nodes['policy']['context_source'] == '/r1/context_estimator'
    assert d.plan(clock='/sim/clock').remappings == [('/clock', '/sim/clock')]
    assert d.plan().remappings == []
    params = tmp_path / 'p.yaml'
    params.write_text('/**/sim_bridge:\n  ros__parameters:\n    action_sender: /mine\n')
    assert 'action_sender' not in d.plan(params_file=params, nodes=['sim_bridge']).nodes[0] \
        .parameters
    with pytest.raises(ValueError, match='needs a namespace'):
        d.plan(clock='namespace')
    with pytest.raises(ValueError, match='absolute topic'):
        d.plan(clock='clock')


def test_relative_checkpoint_resolves_next_to_the_params_file(tmp_path: Path,
                                                              monkeypatch: Any) -> None:
    """`checkpoint: mine.pt` is the file beside the params file.

    A missing one is an error naming every place looked in.
    """
    from zeus_ros.system import launch_defaults as d

    (tmp_path / 'cfg').mkdir()
    (tmp_path / 'cfg' / 'mine.pt').write_bytes(b'x')
    params = tmp_path / 'cfg' / 'p.yaml'
    params.write_text('/**/policy:\n  ros__parameters:\n    checkpoint: mine.pt\n')
    monkeypatch.chdir(tmp_path)
    plan = d.plan(params_file='cfg/p.yaml', nodes=['sim_bridge', 'policy'])
    assert plan.params_file == params
    assert plan.nodes[1].parameters == {'checkpoint': str(tmp_path / 'cfg' / 'mine.pt'),
                                        'expected_subscribers': 1,
                                        'step_source': '/sim_bridge'}
    params.write_text('policy:\n  ros__parameters:\n    checkpoint: typo.pt\n')
    with pytest.raises(ValueError, match=r"policy checkpoint .*'typo.pt' not found; looked "
                       rf'in: {tmp_path}/cfg/typo.pt, .*share.*'):
        d.plan(params_file=params, nodes=['policy'])
    with pytest.raises(ValueError, match='does not exist'):
        d.plan(params_file=tmp_path / 'none.yaml')


def test_launch_file_starts_what_zeus_launch_starts(monkeypatch: Any) -> None:
    """The installed zeus.launch.py starts the nodes `zeus launch` starts, with the same args.

    It declares the shared arguments; for record:=true in a namespace on sim time it builds the
    nodes, parameters and ROS arguments `zeus launch` gives its children.
    """
    from zeus_ros.cli.launch import plan_processes
    from zeus_ros.system import launch_defaults as d

    *declared, opaque = installed_launch_description(monkeypatch)
    defaults = {a.args[0]: a.kwargs['default_value'] for a in declared}
    assert list(defaults) == [a.name for a in d.ARGUMENTS]
    assert defaults['params_file'] == str(d.default_params_file())
    context = {**defaults, 'record': 'true', 'namespace': 'r1', 'use_sim_time': 'true',
               'clock': 'namespace'}
    actions = opaque.kwargs['function'](context)
    nodes = [a for a in actions if type(a).__name__ == 'Node']
    stops = [a for a in actions if type(a).__name__ == 'RegisterEventHandler']
    plan = d.plan(record=True, namespace='r1', use_sim_time=True, clock='namespace')
    assert len(stops) == 4 and len(nodes) == 4  # every process's exits are handled
    children = plan_processes(plan)
    for node, planned, child in zip(nodes, plan.nodes, children, strict=True):
        kwargs = node.kwargs
        assert (kwargs['executable'], kwargs['name'], kwargs['namespace']) == (
            f'{planned.name}_node', planned.name, '/r1')
        assert kwargs['parameters'] == [str(plan.params_file), planned.parameters]
        assert kwargs['remappings'] == [('/clock', '/r1/clock')]  # the system's own clock
        assert len(kwargs['additional_env']['ZEUS_PAIRING_KEY']) == 32  # one key per launch
        assert child.argv[-len(plan.ros_args(planned)):] == plan.ros_args(planned)
    assert nodes[0].kwargs['parameters'][1]['min_observers'] == 3


def _launch(cwd: Path, *flags: str) -> str:
    """Run `zeus launch --record` with the installed files in `cwd`; its output (exit 0)."""
    result = subprocess.run(
        [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--record', '--timeout', '25', *flags],
        cwd=cwd, env=ros_environment(fresh_domain_id()), capture_output=True, text=True,
        timeout=150, check=False)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-3000:]
    return output


def _recorded_steps(cwd: Path) -> list[int]:
    """The step indices of the one Jazzy bag a launch recorded under ./bags."""
    from rosbags.highlevel import AnyReader

    [bag] = (cwd / 'bags').glob('zeus_*/zeus_*_000')
    assert 'version: 9' in (bag / 'metadata.yaml').read_text()
    with AnyReader([bag]) as reader:
        return sorted(int(reader.deserialize(raw, conn.msgtype).step)
                      for conn, _, raw in reader.messages() if conn.topic == '/zeus/step')


@pytest.mark.alone  # every step of a free-running lockstep loop in the recorder's bag
def test_zeus_launch_without_params_runs_from_any_folder(tmp_path: Path) -> None:
    """`zeus launch --record` without --params, outside the repository, runs the installed files.

    The installed params and shipped checkpoint drive the loop; the recorder, counted in
    min_observers, has step 0 and every step after it in a Jazzy bag under ./bags.
    """
    output = _launch(tmp_path, '--log-level', 'warn')
    assert 'share/zeus_ros/params/zeus.yaml' in output and 'min_observers' in output
    steps = _recorded_steps(tmp_path)
    assert len(steps) > 50 and steps == list(range(len(steps))), steps[:10]


@pytest.mark.alone  # every step of a free-running lockstep loop in the recorder's bag
def test_single_process_runs_the_same_loop_in_one_process(tmp_path: Path) -> None:
    """--single-process: one container child holds the three nodes under their own names.

    The namespace and the installed params reach every node as in multi-process mode, the
    time limit's SIGINT (Ctrl-C) stops the container with exit 0, and the recorder (its own
    process) has every step from 0 on.
    """
    output = _launch(tmp_path, '--single-process', '--namespace', 'r1', '--no-progress')
    assert 'exit codes: container 0, recorder 0' in output, output[-3000:]
    for name in ('sim_bridge', 'context_estimator', 'policy'):
        assert '[container] [INFO] [' in output and f'[r1.{name}]:' in output, name
    assert 'paired with /r1/policy' in output and 'restarted' not in output
    steps = _recorded_steps(tmp_path)
    assert len(steps) > 50 and steps == list(range(len(steps))), steps[:10]


def test_container_arguments_give_each_node_its_own(monkeypatch: Any) -> None:
    """single_process:=true: the launch file starts the container `zeus launch` starts.

    Inside, each node has the --ros-args its own process would get; bad arguments are refused.
    """
    from zeus_ros.cli.launch import plan_processes
    from zeus_ros.nodes.container import parse_container_args
    from zeus_ros.system import launch_defaults as d

    *declared, opaque = installed_launch_description(monkeypatch)
    context = {**{a.args[0]: a.kwargs['default_value'] for a in declared},
               'record': 'true', 'namespace': 'r1', 'single_process': 'true'}
    nodes = [a for a in opaque.kwargs['function'](context) if type(a).__name__ == 'Node']
    plan = d.plan(record=True, namespace='r1', single_process=True)
    [loop, recorder] = plan_processes(plan)
    assert [n.kwargs['executable'] for n in nodes] == ['loop_container', 'recorder_node']
    assert 'name' not in nodes[0].kwargs and 'namespace' not in nodes[0].kwargs
    assert loop.argv[-len(plan.container_args()):] == nodes[0].kwargs['arguments']
    process, inside = parse_container_args(nodes[0].kwargs['arguments'])
    assert process == ['--ros-args', '--log-level', 'info']
    assert [name for name, _args in inside] == ['sim_bridge', 'context_estimator', 'policy']
    for (name, args), planned in zip(inside, plan.contained, strict=True):
        assert args == ['--ros-args', *plan.ros_args(planned)], name
    assert 'min_observers:=3' in inside[0][1] and recorder.name == 'recorder'
    for bad, match in ((['--node', 'nope'], 'unknown node'), ([], 'no node to run'),
                       (['--node', 'policy', '--node', 'policy'], 'given twice')):
        with pytest.raises(ValueError, match=match):
            parse_container_args(bad)
    # intra_process:=false: the same container, its nodes' messages through DDS
    off = d.plan_from_arguments({'single_process': 'true', 'intra_process': 'false'})
    assert off.container_args()[0] == d.CONTAINER_NO_INTRA
    assert d.CONTAINER_NO_INTRA not in plan.container_args()
    with pytest.raises(ValueError, match='applies to single_process only'):
        d.plan_from_arguments({'intra_process': 'false'})


def test_a_node_finds_the_shipped_checkpoint_from_any_folder(tmp_path: Path,
                                                             monkeypatch: Any) -> None:
    """A node run elsewhere with the installed params finds their checkpoint in the share.

    (`ros2 run ... --params-file share/zeus_ros/params/zeus.yaml`.) It knows the absolute path
    and sha256 it loaded.
    """
    import hashlib

    from zeus_ros.nodes.agent_loader import load_inference_agent
    from zeus_ros.system.launch_defaults import share_dir

    monkeypatch.chdir(tmp_path)
    relative = 'checkpoints/cheetah_bias_v0/zeus.pt'  # the zoo: what the package installs
    loaded = load_inference_agent('policy', {'checkpoint': relative, 'task': 'Cheetah-Bias-v0',
                                             'device': 'cpu', 'torch_threads': 1})
    assert loaded.path == share_dir() / relative
    assert loaded.sha256 == hashlib.sha256(loaded.path.read_bytes()).hexdigest()
    assert loaded.describe() == f'{loaded.path} (sha256 {loaded.sha256})'
    with pytest.raises(ValueError, match=r"policy: parameter checkpoint 'nope.pt' not found"):
        load_inference_agent('policy', {'checkpoint': 'nope.pt', 'task': '', 'device': 'cpu',
                                        'torch_threads': 1})


def test_nodes_of_one_process_share_the_agent_of_one_checkpoint(tmp_path: Path) -> None:
    """Estimator and policy in one container hold one copy of the networks and phi's memo.

    A copy of the file is the same checkpoint (same sha256); another task expectation, or an
    agent no node holds any more, loads afresh.
    """
    import gc
    import shutil
    import weakref

    from zeus_ros.nodes.agent_loader import load_inference_agent
    from zeus_ros.system.launch_defaults import share_dir

    shipped = share_dir() / 'checkpoints/cheetah_bias_v0/zeus.pt'
    copy = tmp_path / 'copy.pt'
    shutil.copyfile(shipped, copy)
    params = {'checkpoint': str(shipped), 'task': '', 'device': 'cpu', 'torch_threads': 1}
    estimator = load_inference_agent('context_estimator', params)
    policy = load_inference_agent('policy', {**params, 'checkpoint': str(copy)})
    assert policy.agent is estimator.agent and policy.agent.reuse_features
    assert sorted(policy.agent.agent.modules) == ['actor', 'encoder', 'psi']  # no critics
    assert policy.path == copy
    checked = load_inference_agent('policy', {**params, 'task': 'Cheetah-Bias-v0'})
    assert checked.agent is not estimator.agent
    shared = weakref.ref(estimator.agent)
    del estimator, policy
    gc.collect()
    assert shared() is None  # a redeployed checkpoint's networks do not stay in memory
    assert load_inference_agent('policy', params).agent.reuse_features


def test_lock_parameters_goes_to_the_loop_nodes_only() -> None:
    """--lock-parameters / lock_parameters:=true: bridges, estimator, policy; not the others."""
    from zeus_ros.system import launch_defaults as d

    locked = {n.name: n.parameters.get('lock_parameters')
              for n in d.plan(record=True, lock_parameters=True).nodes}
    assert locked == {'sim_bridge': True, 'context_estimator': True, 'policy': True,
                      'recorder': None}, locked
    assert all('lock_parameters' not in n.parameters for n in d.plan(record=True).nodes)
    from_arguments = d.plan_from_arguments({'lock_parameters': 'true'})
    assert all(n.parameters['lock_parameters'] for n in from_arguments.nodes)
