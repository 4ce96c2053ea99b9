"""Standard robot messages <-> arrays: JointState in, ros2_control-style commands out.

Out: the action (in `action_joints` order) becomes a Float64MultiArray for a forward command
controller (`~/commands`, values in `command_joints` order), a single-point JointTrajectory
reaching its positions one control period from now, or a Twist / TwistStamped for a mobile
base (Jazzy's diff_drive_controller takes TwistStamped).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from sensor_msgs.msg import Image, JointState

from sim_bridge.robot import joint_indices
from zeus_ros.nodes.topics import action_qos

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ['COMMAND_TYPES', 'CommandPublisher', 'frame_from_camera', 'hold_positions',
           'parse_safe_command', 'read_joint_state']

COMMAND_TYPES = ('float64_multi_array', 'joint_trajectory', 'twist', 'twist_stamped')
TWIST_FIELDS = tuple(f'{part}.{axis}' for part in ('linear', 'angular') for axis in 'xyz')


def read_joint_state(msg: JointState, joints: Sequence[str], fields: Sequence[str]
                     ) -> dict[str, dict[str, float]]:
    """Values of `joints` for each of `fields`, picked by name; ValueError says what is wrong."""
    try:
        order = joint_indices(list(msg.name), joints)
    except KeyError as error:
        raise ValueError(f'JointState lacks joint(s) {error.args[0]} (it has {list(msg.name)})'
                         ) from None
    out: dict[str, dict[str, float]] = {}
    for field in fields:
        values = getattr(msg, field)
        if len(values) != len(msg.name):
            raise ValueError(f'JointState {field} has {len(values)} values for '
                             f'{len(msg.name)} names (the robot does not publish {field}?)')
        picked = {name: float(values[i]) for name, i in zip(joints, order, strict=True)}
        bad = [name for name, value in picked.items() if not math.isfinite(value)]
        if bad:
            raise ValueError(f'JointState {field} of {bad} is NaN/Inf')
        out[field] = picked
    return out


class CommandPublisher:
    """Publishes an action vector as the robot's command message, in the controller's order."""

    def __init__(self, node: Node, kind: str, topic: str, action_joints: Sequence[str],
                 command_joints: Sequence[str], twist_fields: Sequence[str],
                 period: float) -> None:
        if kind not in COMMAND_TYPES:
            raise ValueError(f'robot_bridge: command_type {kind!r}: choose one of '
                             f'{", ".join(COMMAND_TYPES)}')
        self.kind = kind
        self.period = period
        self.frame_id = 'base_link'  # twist_stamped: the base frame, as diff_drive_controller
        self._clock = node.get_clock()
        self.command_joints = list(command_joints or action_joints)
        if sorted(self.command_joints) != sorted(action_joints):
            raise ValueError(f'robot_bridge: command_joints {self.command_joints} must name the '
                             f'same joints as action_joints {list(action_joints)} (any order)')
        self.order = joint_indices(list(action_joints), self.command_joints)
        self.twist_fields = list(twist_fields)
        if kind.startswith('twist'):
            bad = [f for f in self.twist_fields if f not in TWIST_FIELDS]
            if bad or len(self.twist_fields) != len(action_joints):
                raise ValueError(f'robot_bridge: twist_fields {self.twist_fields} need one of '
                                 f'{list(TWIST_FIELDS)} per action value ({len(action_joints)})')
        self._message = self._message_class()
        self.publisher = node.create_publisher(self._message, topic, action_qos('realtime'))

    def _message_class(self) -> Any:
        if self.kind == 'float64_multi_array':
            from std_msgs.msg import Float64MultiArray

            return Float64MultiArray
        if self.kind == 'joint_trajectory':
            from trajectory_msgs.msg import JointTrajectory

            return JointTrajectory
        from geometry_msgs.msg import Twist, TwistStamped

        return Twist if self.kind == 'twist' else TwistStamped

    def message(self, action: np.ndarray) -> Any:
        """The command message for `action` (action order in, controller order out)."""
        values = [float(action[i]) for i in self.order]
        msg = self._message()
        if self.kind == 'float64_multi_array':
            msg.data = values
        elif self.kind == 'joint_trajectory':
            from builtin_interfaces.msg import Duration
            from trajectory_msgs.msg import JointTrajectoryPoint

            nanoseconds = round(self.period * 1e9)
            msg.joint_names = self.command_joints
            msg.points = [JointTrajectoryPoint(
                positions=values, time_from_start=Duration(
                    sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000))]
        else:
            twist = msg if self.kind == 'twist' else msg.twist
            if self.kind == 'twist_stamped':
                msg.header.stamp = self._clock.now().to_msg()
                msg.header.frame_id = self.frame_id
            for name, value in zip(self.twist_fields, (float(v) for v in action), strict=True):
                part, axis = name.split('.')
                setattr(getattr(twist, part), axis, value)
        return msg

    def publish(self, action: np.ndarray) -> None:
        """Send `action` to the robot."""
        self.publisher.publish(self.message(action))


_CHANNELS = {'rgb8': (3, [0, 1, 2]), 'bgr8': (3, [2, 1, 0]), 'rgba8': (4, [0, 1, 2]),
             'bgra8': (4, [2, 1, 0]), 'mono8': (1, [0, 0, 0])}


def frame_from_camera(msg: Image, size: int) -> np.ndarray:
    """A camera Image as the size x size rgb8 frame our agents see: centre square, nearest pixel.

    ValueError for an encoding other than rgb8/bgr8/rgba8/bgra8/mono8 or inconsistent data.
    """
    if msg.encoding not in _CHANNELS:
        raise ValueError(f'image encoding {msg.encoding!r}: use one of {", ".join(_CHANNELS)}')
    channels, order = _CHANNELS[msg.encoding]
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height < 1 or width < 1 or step < width * channels or len(msg.data) < step * height:
        raise ValueError(f'image data has {len(msg.data)} bytes for {height}x{width} '
                         f'{msg.encoding} with row step {step}')
    rows = np.frombuffer(bytes(msg.data), np.uint8)[:step * height].reshape(height, step)
    pixels = rows[:, :width * channels].reshape(height, width, channels)
    side = min(height, width)
    top, left = (height - side) // 2, (width - side) // 2
    pick = (np.arange(size) * side // size)
    square = pixels[top + pick[:, None], left + pick[None, :]]
    return np.ascontiguousarray(square[:, :, order])


def parse_safe_command(text: str, low: np.ndarray, high: np.ndarray) -> np.ndarray | str:
    """'' -> zeros clipped into the limits; 'hold' -> 'hold'; 'a,b,...' -> those values."""
    text = text.strip()
    if not text:
        return np.clip(np.zeros_like(low), low, high)
    if text == 'hold':
        return 'hold'
    try:
        values = np.asarray([float(v) for v in text.split(',')], dtype=np.float64)
    except ValueError:
        values = np.full(0, math.nan)
    if values.shape != low.shape or not np.all((values >= low) & (values <= high)):
        raise ValueError(f"robot_bridge: parameter safe_command={text!r}: give '' (zeros), "
                         f"'hold' (keep the measured positions) or {low.size} comma-separated "
                         f'values within action_low / action_high')
    return values


def hold_positions(positions: Mapping[str, float], joints: Sequence[str]) -> np.ndarray | None:
    """The measured positions of `joints` (the 'hold' safe command), or None if unknown."""
    if not all(name in positions for name in joints):
        return None
    return np.asarray([positions[name] for name in joints], dtype=np.float64)
