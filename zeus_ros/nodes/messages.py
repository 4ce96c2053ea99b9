"""Message conversions every node shares: stamps and rgb8 images (/diagnostics: diagnostics.py)."""

from __future__ import annotations

from builtin_interfaces.msg import Time
import numpy as np
from sensor_msgs.msg import Image

from zeus_ros.nodes.diagnostics import diagnostics_message

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
