"""The one bag schema: topics, message types, the typestore and message codecs.

`zeus collect` (in-process) and the live recorder both write through this module, so a bag
from either source decodes the same way. The zeus_msgs definitions come from the .msg files of
this checkout (`msg_defs/msg`), or, in an installed workspace, from `share/zeus_msgs/msg` under
an `AMENT_PREFIX_PATH` entry.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from zeus_ros.bags.errors import SchemaError

if TYPE_CHECKING:
    from collections.abc import Sequence

    from rosbags.typesys.store import Typestore

__all__ = [
    'ACTION_STATUS_NONE',
    'FRAME_ID',
    'IMAGE_ENCODING',
    'IMAGE_FRAME_ID',
    'MSGTYPES',
    'OFFERED_QOS',
    'QOS_INFINITE',
    'TOPIC_ACTION',
    'TOPIC_CLOCK',
    'TOPIC_CONTEXT',
    'TOPIC_CONTEXT_TRUTH',
    'TOPIC_IMAGE',
    'TOPIC_STATE',
    'TOPIC_STEP',
    'ZEUS_MSG_NAMES',
    'Codec',
    'codec',
    'find_msg_dir',
    'graph_qos',
    'ns_from_sim_time',
    'ns_from_stamp',
    'typestore',
]

TOPIC_STATE = '/zeus/observation/state'
TOPIC_IMAGE = '/zeus/observation/image'
TOPIC_STEP = '/zeus/step'
TOPIC_CONTEXT_TRUTH = '/zeus/context_truth'
TOPIC_CLOCK = '/clock'
TOPIC_ACTION = '/zeus/action'
TOPIC_CONTEXT = '/zeus/context'

MSGTYPES: dict[str, str] = {
    TOPIC_STATE: 'zeus_msgs/msg/StateVector',
    TOPIC_IMAGE: 'sensor_msgs/msg/Image',
    TOPIC_STEP: 'zeus_msgs/msg/StepFeedback',
    TOPIC_CONTEXT_TRUTH: 'zeus_msgs/msg/ContextTruth',
    TOPIC_CLOCK: 'rosgraph_msgs/msg/Clock',
    TOPIC_ACTION: 'zeus_msgs/msg/Action',
    TOPIC_CONTEXT: 'zeus_msgs/msg/ContextEstimate',
}
"""Every topic a bag may hold, with its message type."""

QOS_INFINITE = QosTime(sec=9223372036, nsec=854775807)
"""An infinite deadline / lifespan / lease, as the ROS graph reports it (rmw's infinity)."""


def graph_qos(reliability: QosReliability = QosReliability.RELIABLE,
              durability: QosDurability = QosDurability.VOLATILE) -> Qos:
    """A publisher's QoS as the ROS graph (and so `ros2 bag record`) reports it.

    Discovery does not carry history and depth, so they read UNKNOWN / 0 there too.
    """
    return Qos(history=QosHistory.UNKNOWN, depth=0, reliability=reliability,
               durability=durability, deadline=QOS_INFINITE, lifespan=QOS_INFINITE,
               liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=QOS_INFINITE,
               avoid_ros_namespace_conventions=False)


OFFERED_QOS: dict[str, tuple[Qos, ...]] = {topic: (graph_qos(),) for topic in MSGTYPES}
"""What the zeus publishers offer in lockstep mode (reliable, volatile: nodes/topics.py
step_qos), one publisher per topic. `zeus collect` bags carry these; the recorder asks the
graph."""

ZEUS_MSG_NAMES = ('Action', 'ContextEstimate', 'ContextTruth', 'StateVector', 'StepFeedback')
FRAME_ID = ''
"""header.frame_id of the state, step, context and action messages (as the nodes publish)."""
IMAGE_FRAME_ID = 'camera'
IMAGE_ENCODING = 'rgb8'
ACTION_STATUS_NONE = 0
"""StepFeedback.ACTION_NONE: no action was applied (the reset observation)."""


def find_msg_dir() -> Path:
    """Directory holding the zeus_msgs .msg files: this checkout, else an ament share dir."""
    tried: list[str] = []
    repo_dir = Path(__file__).resolve().parents[3] / 'msg_defs' / 'msg'
    candidates = [repo_dir]
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            candidates.append(Path(prefix) / 'share' / 'zeus_msgs' / 'msg')
    for cand in candidates:
        tried.append(str(cand))
        if all((cand / f'{name}.msg').is_file() for name in ZEUS_MSG_NAMES):
            return cand
    raise SchemaError(
        'zeus_msgs .msg definitions not found; looked in: '
        + ', '.join(tried)
        + '. Run from a repo checkout (msg_defs/msg) or source a workspace where zeus_msgs '
        'is installed (its share/zeus_msgs/msg must be on AMENT_PREFIX_PATH).'
    )


@cache
def typestore() -> Typestore:
    """ROS 2 Jazzy typestore with zeus_msgs registered (built once per process)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    msg_dir = find_msg_dir()
    types: dict[str, Any] = {}
    for name in ZEUS_MSG_NAMES:
        path = msg_dir / f'{name}.msg'
        try:
            types.update(get_types_from_msg(path.read_text(), f'zeus_msgs/msg/{name}'))
        except Exception as exc:  # rosbags raises several parser error types
            raise SchemaError(f'{path}: cannot parse message definition: {exc}') from exc
    store.register(types)
    return store


def ns_from_sim_time(seconds: float) -> int:
    """Convert simulation time in seconds to integer nanoseconds (stamps, bag times)."""
    return round(seconds * 1e9)


def ns_from_stamp(stamp: Any) -> int:
    """builtin_interfaces/Time to integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


@dataclass(frozen=True)
class StepFeedbackFields:
    """The StepFeedback fields besides header and step, as the simulator fills them."""

    episode: int
    episode_step: int
    first: bool
    last: bool
    reward: float
    applied_action: np.ndarray
    action_status: int
    task: str


class Codec:
    """Builds messages from arrays and serializes them to CDR; decodes them back.

    Arrays go into messages as numpy arrays (one buffer copy per field, never per element).
    """

    def __init__(self, store: Typestore) -> None:
        self.store = store
        types = store.types
        self._time = types['builtin_interfaces/msg/Time']
        self._header = types['std_msgs/msg/Header']
        self._state = types['zeus_msgs/msg/StateVector']
        self._image = types['sensor_msgs/msg/Image']
        self._feedback = types['zeus_msgs/msg/StepFeedback']
        self._truth = types['zeus_msgs/msg/ContextTruth']
        self._clock = types['rosgraph_msgs/msg/Clock']
        self._action = types['zeus_msgs/msg/Action']
        self._estimate = types['zeus_msgs/msg/ContextEstimate']

    def header(self, stamp_ns: int, frame_id: str = FRAME_ID) -> Any:
        """std_msgs/Header with the step's simulation-time stamp."""
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        return self._header(stamp=self._time(sec=sec, nanosec=nanosec), frame_id=frame_id)

    def serialize(self, msg: Any) -> bytes:
        """CDR bytes of a message built by this codec."""
        return bytes(self.store.serialize_cdr(msg, msg.__msgtype__))

    def deserialize(self, raw: bytes | memoryview, msgtype: str) -> Any:
        """Message object from CDR bytes; arrays come back as numpy views of `raw`."""
        return self.store.deserialize_cdr(raw, msgtype)

    def state(self, step: int, stamp_ns: int, data: np.ndarray) -> Any:
        """zeus_msgs/StateVector for observation o_step."""
        return self._state(
            header=self.header(stamp_ns),
            step=int(step),
            data=np.ascontiguousarray(data, dtype=np.float64).reshape(-1),
        )

    def image(self, stamp_ns: int, frame: np.ndarray) -> Any:
        """sensor_msgs/Image (rgb8) from an H x W x 3 uint8 frame."""
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
            raise ValueError(f'image frame must be HxWx3 uint8, got {frame.shape} {frame.dtype}')
        height, width = int(frame.shape[0]), int(frame.shape[1])
        return self._image(
            header=self.header(stamp_ns, IMAGE_FRAME_ID),
            height=height,
            width=width,
            encoding=IMAGE_ENCODING,
            is_bigendian=0,
            step=width * 3,
            data=np.ascontiguousarray(frame).reshape(-1),
        )

    def feedback(self, step: int, stamp_ns: int, fields: StepFeedbackFields) -> Any:
        """zeus_msgs/StepFeedback: reward r_step and the action applied before o_step."""
        return self._feedback(
            header=self.header(stamp_ns),
            step=int(step),
            episode=int(fields.episode),
            episode_step=int(fields.episode_step),
            first=bool(fields.first),
            last=bool(fields.last),
            reward=float(fields.reward),
            applied_action=np.ascontiguousarray(fields.applied_action, dtype=np.float32).ravel(),
            action_status=int(fields.action_status),
            task=fields.task,
        )

    def truth(
        self,
        step: int,
        stamp_ns: int,
        names: Sequence[str],
        values: np.ndarray,
        segment: int,
    ) -> Any:
        """zeus_msgs/ContextTruth: the true context c_step."""
        vals = np.ascontiguousarray(values, dtype=np.float64).reshape(-1)
        if len(names) != vals.shape[0]:
            raise ValueError(f'context names ({len(names)}) and values ({vals.shape[0]}) differ')
        return self._truth(
            header=self.header(stamp_ns),
            step=int(step),
            names=list(names),
            values=vals,
            segment=int(segment),
        )

    def clock(self, stamp_ns: int) -> Any:
        """rosgraph_msgs/Clock carrying the simulation time."""
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        return self._clock(clock=self._time(sec=sec, nanosec=nanosec))

    def action(self, step: int, stamp_ns: int, data: np.ndarray) -> Any:
        """zeus_msgs/Action a_step (stamp of the observation it answers)."""
        return self._action(
            header=self.header(stamp_ns),
            step=int(step),
            data=np.ascontiguousarray(data, dtype=np.float32).reshape(-1),
        )

    def estimate(
        self,
        step: int,
        stamp_ns: int,
        data: np.ndarray,
        history_length: int,
        missing_steps: int = 0,
        checkpoint_sha256: str = '',
    ) -> Any:
        """zeus_msgs/ContextEstimate psi(H_step), from the checkpoint with that sha256."""
        return self._estimate(
            header=self.header(stamp_ns),
            step=int(step),
            data=np.ascontiguousarray(data, dtype=np.float32).reshape(-1),
            history_length=int(history_length),
            missing_steps=int(missing_steps),
            checkpoint_sha256=checkpoint_sha256,
        )


@cache
def codec() -> Codec:
    """Return the process-wide codec over `typestore()`."""
    return Codec(typestore())
