"""A robot's declaration (robot_bridge params): validation, rewards, commands, the task shape."""

from __future__ import annotations

from pathlib import Path
import subprocess

import numpy as np
import pytest
import yaml

from sim_bridge.registry import is_simulated, make_task, register_task_file
from sim_bridge.rewards import JointObservation, load_reward
from sim_bridge.robot import RobotSpec, robot_section

from ros_harness import REPO, driver_node, fresh_domain_id, python_module, ros_environment

PARAMS = REPO / 'params' / 'robot_bridge.yaml'


def robot_params(**changes: object) -> dict:
    """The example robot's parameters with some changed."""
    params = dict(robot_section(yaml.safe_load(PARAMS.read_text())))
    params.update(changes)
    return params


def test_the_params_file_declares_the_task_shape_for_the_tools() -> None:
    """make_task on the params file: bounds, state size, context; it refuses to step."""
    task = make_task(str(PARAMS))
    assert task.name == 'FakeArm-v0' and task.state_dim == 5  # 2 joints x (pos, vel) + payload
    low, high = task.action_bounds
    assert low.tolist() == [-1.0, -1.0] and high.tolist() == [1.0, 1.0]
    assert task.context_names == ('payload_kg',) and task.context == {'payload_kg': 0.5}
    with pytest.raises(ValueError, match=r'is a robot .*robot_bridge_node'):
        task.reset()
    assert register_task_file(PARAMS) == 'FakeArm-v0'
    assert make_task('FakeArm-v0').state_dim == 5 and not is_simulated('FakeArm-v0')
    assert is_simulated('Cheetah-Run-v0')


@pytest.mark.parametrize(('changes', 'message'), [
    ({'joints': ['']}, 'parameter joints is required'),
    ({'observe': ['position', 'torque']}, r"observe=\['position', 'torque'\]: choose among"),
    ({'extra_inputs': ['imu']}, "extra_inputs: 'imu' must be TOPIC:SIZE"),
    ({'action_low': [-1.0]}, 'action_low / action_high need 2 finite values'),
    ({'action_high': [-2.0, 1.0]}, 'with low < high'),
    ({'context': 'payload'}, "context: 'payload' must be NAME=NUMBER"),
    ({'joints': ['elbow', 'elbow']}, 'lists a name twice'),
])
def test_a_bad_declaration_names_the_parameter_and_the_fix(changes: dict, message: str) -> None:
    """One line that says which parameter and what it should look like."""
    with pytest.raises(ValueError, match=message):
        RobotSpec.from_params(robot_params(**changes))


def test_a_bad_task_file_is_one_line_naming_it(tmp_path: Path) -> None:
    """Broken YAML, a missing file and a file of neither kind."""
    broken = tmp_path / 'broken.yaml'
    broken.write_text('a: [1, 2\n')
    with pytest.raises(ValueError, match=r'broken.yaml line \d+: not valid YAML'):
        make_task(str(broken))
    with pytest.raises(ValueError, match='does not exist'):
        make_task(str(tmp_path / 'missing.yaml'))
    other = tmp_path / 'other.yaml'
    other.write_text('policy:\n  ros__parameters: {}\n')
    with pytest.raises(ValueError, match='expected a robot_bridge: ros__parameters: section'):
        make_task(str(other))


def test_rewards_built_in_and_a_users_function(tmp_path: Path, monkeypatch) -> None:
    """velocity:JOINT, tracking:J=T and package.module:function with (obs, action, prev)."""
    obs = JointObservation(state=np.zeros(4), position={'a': 0.5, 'b': -1.0},
                           velocity={'a': 2.0, 'b': 3.0})
    joints, fields = ('a', 'b'), ('position', 'velocity')
    assert load_reward('velocity:b', joints, fields)(obs, None, None) == 3.0
    assert load_reward('tracking:a=1,b=-1', joints, fields)(obs, None, None) == -0.25
    (tmp_path / 'my_rewards.py').write_text(
        'def upright(obs, action, prev_obs):\n'
        '    return obs.position["a"] - (0.0 if prev_obs is None else prev_obs.position["a"])\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    assert load_reward('my_rewards:upright', joints, fields)(obs, None, obs) == 0.0
    for spec, message in [('velocity:c', "no joint 'c'"), ('tracking:a', 'JOINT=NUMBER'),
                          ('nowhere.mod:f', "cannot import module 'nowhere.mod'"),
                          ('my_rewards:missing', "has no function 'missing'"),
                          ('forward', 'give a built-in')]:
        with pytest.raises(ValueError, match=message):
            load_reward(spec, joints, fields)
    with pytest.raises(ValueError, match="needs 'velocity' among the observed fields"):
        load_reward('velocity:a', joints, ('position',))


def test_command_messages_follow_the_controllers_order() -> None:
    """Float64MultiArray, single-point JointTrajectory (one period ahead), Twist(Stamped)."""
    from zeus_ros.nodes.robot_io import CommandPublisher, hold_positions, parse_safe_command

    action = np.asarray([0.25, -0.5])
    with driver_node(fresh_domain_id()) as node:
        array = CommandPublisher(node, 'float64_multi_array', 'a', ['shoulder', 'elbow'],
                                 ['elbow', 'shoulder'], [], 0.02).message(action)
        assert list(array.data) == [-0.5, 0.25]
        trajectory = CommandPublisher(node, 'joint_trajectory', 'b', ['shoulder', 'elbow'],
                                      ['elbow', 'shoulder'], [], 0.02).message(action)
        assert list(trajectory.joint_names) == ['elbow', 'shoulder']
        [point] = trajectory.points
        assert list(point.positions) == [-0.5, 0.25]
        assert (point.time_from_start.sec, point.time_from_start.nanosec) == (0, 20_000_000)
        twist = CommandPublisher(node, 'twist', 'c', ['drive', 'steer'], [],
                                 ['linear.x', 'angular.z'], 0.02).message(action)
        assert (twist.linear.x, twist.angular.z, twist.linear.y) == (0.25, -0.5, 0.0)
        stamped = CommandPublisher(node, 'twist_stamped', 'f', ['drive', 'steer'], [],
                                   ['linear.x', 'angular.z'], 0.02).message(action)
        assert (stamped.twist.linear.x, stamped.twist.angular.z) == (0.25, -0.5)
        assert stamped.header.frame_id == 'base_link' and stamped.header.stamp.sec > 0
        with pytest.raises(ValueError, match='must name the same joints'):
            CommandPublisher(node, 'float64_multi_array', 'd', ['a', 'b'], ['a', 'c'], [], 0.02)
        with pytest.raises(ValueError, match='twist_fields'):
            CommandPublisher(node, 'twist', 'e', ['a', 'b'], [], ['linear.x', 'up'], 0.02)
    low, high = np.asarray([-1.0, 0.5]), np.asarray([1.0, 2.0])
    assert parse_safe_command('', low, high).tolist() == [0.0, 0.5]  # zero, moved into range
    assert parse_safe_command('hold', low, high) == 'hold'
    with pytest.raises(ValueError, match='within action_low / action_high'):
        parse_safe_command('3,1', low, high)
    assert hold_positions({'a': 1.0, 'b': 2.0, 'c': 3.0}, ['c', 'a']).tolist() == [3.0, 1.0]


@pytest.mark.ros
def test_the_node_refuses_a_bad_params_file_in_one_line() -> None:
    """Exit code 2 and one line naming the parameter, no traceback."""
    argv = [*python_module('zeus_ros.nodes.robot_bridge_node'), '--ros-args', '--params-file',
            str(PARAMS), '-p', 'reward:=velocity:knee']
    result = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=60,
                            env=ros_environment(fresh_domain_id()))
    assert result.returncode == 2, result.stderr
    assert "error: reward velocity:knee: no joint 'knee'" in result.stderr
    assert 'Traceback' not in result.stderr


def test_a_camera_frame_becomes_our_square_rgb8_frame() -> None:
    """bgr8 channels swapped, the centre square resized; other encodings refused."""
    from sensor_msgs.msg import Image

    from zeus_ros.nodes.robot_io import frame_from_camera

    pixels = np.zeros((4, 8, 3), np.uint8)
    pixels[:, 2:6] = (10, 20, 30)  # the centre 4x4 square, in b, g, r
    msg = Image(height=4, width=8, encoding='bgr8', step=8 * 3 + 2,
                data=np.pad(pixels.reshape(4, 24), ((0, 0), (0, 2))).tobytes())
    frame = frame_from_camera(msg, 2)
    assert frame.shape == (2, 2, 3) and (frame == (30, 20, 10)).all()
    mono = Image(height=2, width=2, encoding='mono8', step=2, data=bytes([7, 7, 7, 7]))
    assert (frame_from_camera(mono, 4) == 7).all()
    with pytest.raises(ValueError, match="image encoding '16UC1'"):
        frame_from_camera(Image(height=1, width=1, encoding='16UC1', step=2, data=b'00'), 2)
    with pytest.raises(ValueError, match='image data has 3 bytes'):
        frame_from_camera(Image(height=2, width=2, encoding='rgb8', step=6, data=b'000'), 2)


def test_both_launchers_put_robot_bridge_in_sim_bridges_place(tmp_path: Path) -> None:
    """robot:=true / --robot: robot_bridge in sim_bridge's place, waiting for the others.

    Without a checkpoint the random policy records alone (its task: the robot's params file).
    """
    from zeus_ros.system.launch_defaults import plan, plan_from_arguments

    checkpoint = tmp_path / 'arm.pt'
    checkpoint.write_bytes(b'')
    launch = plan(robot=True, params_file=PARAMS, record=True, checkpoint=str(checkpoint))
    assert [n.name for n in launch.nodes] == ['robot_bridge', 'context_estimator', 'policy',
                                               'recorder']
    assert launch.nodes[0].parameters['min_observers'] == 3
    assert launch.nodes[0].executable == 'robot_bridge_node'
    assert launch == plan_from_arguments({'robot': 'true', 'params_file': str(PARAMS),
                                          'record': 'true', 'checkpoint': str(checkpoint)})
    first = plan(robot=True, params_file=PARAMS, record=True)
    assert [n.name for n in first.nodes] == ['robot_bridge', 'policy', 'recorder']
    assert first.nodes[0].parameters['min_observers'] == 2
    assert first.nodes[1].parameters['expected_subscribers'] == 2  # robot_bridge + recorder
    assert first.nodes[1].parameters['task'] == str(PARAMS)


def test_obs_pixels_on_a_robot_deploys_its_tasks_pixel_checkpoint() -> None:
    """--robot --obs pixels: the robot task's zoo pixel pair; a robot without a camera refused."""
    from zeus_ros.system.launch_defaults import plan

    cheetah = REPO / 'test' / 'fake_cheetah.yaml'
    launch = plan(robot=True, params_file=cheetah, obs='pixels')
    nodes = {node.name: node.parameters for node in launch.nodes}
    assert list(nodes) == ['robot_bridge', 'context_estimator', 'policy']
    assert {nodes[n]['checkpoint'] for n in ('context_estimator', 'policy')} == {
        str(REPO / 'checkpoints' / 'cheetah_motor_v0' / 'pixels_student.pt')}
    assert 'pixels' not in nodes['robot_bridge']  # sim_bridge's parameter, not the robot's
    with pytest.raises(ValueError, match='sets no robot_bridge image_topic'):
        plan(robot=True, params_file=PARAMS, obs='pixels')


def test_a_recorder_of_realtime_frames_subscribes_to_them_best_effort(tmp_path: Path) -> None:
    """Realtime frames are sensor data; a reliable recorder would match none and record none.

    robot_bridge is always realtime; sim_bridge when its params say so; the params file wins.
    """
    from zeus_ros.system.launch_defaults import plan

    def recorder(params_file: Path, **args: object) -> dict[str, object]:
        launch = plan(params_file=params_file, record=True, **args)
        return next(n.parameters for n in launch.nodes if n.name == 'recorder')

    cheetah = REPO / 'test' / 'fake_cheetah.yaml'
    assert recorder(cheetah, robot=True, obs='pixels')['image_best_effort'] is True
    assert 'image_best_effort' not in recorder(REPO / 'params' / 'zeus.yaml')  # lockstep
    realtime = tmp_path / 'realtime.yaml'
    realtime.write_text('/**/sim_bridge:\n  ros__parameters:\n    mode: realtime\n')
    assert recorder(realtime)['image_best_effort'] is True
    realtime.write_text(realtime.read_text() + '/**/recorder:\n  ros__parameters:\n'
                        '    image_best_effort: false\n')
    assert 'image_best_effort' not in recorder(realtime)
