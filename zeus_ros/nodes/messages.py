"""Message conversions every node shares: stamps, rgb8 images and /diagnostics statuses."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from sensor_msgs.msg import Image

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = [
    'array_from_image',
    'diagnostics_message',
    'image_from_array',
    'seconds_from_stamp',
    'stamp_from_seconds',
    'stamp_ns',
]


def stamp_from_seconds(seconds: float) -> Time:
    """Simulation time in seconds as a builtin_interfaces/Time."""
    nanoseconds = round(seconds * 1e9)
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def stamp_ns(stamp: Time) -> int:
    """A builtin_interfaces/Time as integer nanoseconds (a dictionary key that never rounds)."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def seconds_from_stamp(stamp: Time) -> float:
    """A builtin_interfaces/Time as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def image_from_array(frame: np.ndarray, stamp: Time, frame_id: str = 'camera') -> Image:
    """An HxWx3 uint8 frame as an rgb8 Image, copied as bytes (never element by element)."""
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(frame.shape[0]), int(frame.shape[1])
    msg.encoding = 'rgb8'
    msg.is_bigendian = 0
    msg.step = msg.width * 3
    msg.data = np.ascontiguousarray(frame, dtype=np.uint8).tobytes()
    return msg


def array_from_image(msg: Image, expect_shape: tuple[int, int] | None = None) -> np.ndarray:
    """Decode an rgb8 Image to HxWx3 uint8; raise ValueError saying what is wrong with it."""
    if msg.encoding != 'rgb8':
        raise ValueError(f'image encoding is {msg.encoding!r}, expected rgb8')
    if expect_shape is not None and (msg.height, msg.width) != tuple(expect_shape):
        raise ValueError(
            f'image is {msg.height}x{msg.width}, expected {expect_shape[0]}x{expect_shape[1]}'
        )
    expected = msg.height * msg.width * 3
    if msg.step != msg.width * 3 or len(msg.data) != expected:
        raise ValueError(
            f'image data has {len(msg.data)} bytes (row step {msg.step}); '
            f'{msg.height}x{msg.width} rgb8 needs {expected}'
        )
    return np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.width, 3)


def diagnostics_message(
    node: Node, name: str, values: dict[str, object], problems: Sequence[str] = (),
    errors: Sequence[str] = (),
) -> DiagnosticArray:
    """One DiagnosticStatus (ERROR with `errors`, WARN with `problems`, else OK) in an array.

    `problems` are faults the node covers and counts; `errors` need someone to act. A node
    with a start handshake also reports its pairing mode ('keyed' / 'unkeyed'), the hellos it
    refused, and an ERROR naming their senders (handshake.py): the same in every node.
    """
    from zeus_ros.nodes.handshake import pairing_diagnostics

    pairing_values, pairing_errors = pairing_diagnostics(node)
    values = {**values, **pairing_values}
    errors = [*errors, *pairing_errors]
    status = DiagnosticStatus()
    status.name = f'{node.get_fully_qualified_name()}: {name}'
    status.hardware_id = 'zeus_ros'
    status.level = (DiagnosticStatus.ERROR if errors else
                    DiagnosticStatus.WARN if problems else DiagnosticStatus.OK)
    status.message = '; '.join([*errors, *problems]) or 'ok'
    status.values = [KeyValue(key=key, value=str(value)) for key, value in values.items()]
    array = DiagnosticArray()
    array.header.stamp = node.get_clock().now().to_msg()
    array.status = [status]
    return array
