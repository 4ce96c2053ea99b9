"""Write the messages of control steps to a rosbag2 bag (mcap or sqlite3).

Used by `zeus collect` (arrays in) and by the live recorder (CDR bytes from rclpy in). Message
definitions are embedded in the bag (mcap schemas / sqlite3 message_definitions), so `ros2 bag`,
Foxglove or rosbags' AnyReader decode it without this package.

The bag is what Jazzy's rosbag2 writes: metadata version 9, `ros_distro: jazzy`, each topic with
its type hash (RIHS01) and the QoS profiles its publishers offered (so `ros2 bag play` offers the
same), a topic added when its first message arrives. Bag times of `zeus collect` are simulation
time counted from the wall-clock moment the run started, never from 1970.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from io import StringIO
from pathlib import Path
import time
from typing import TYPE_CHECKING, Literal

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from ruamel.yaml import YAML

from zeus_ros.atomic_file import injected_write_fault
from zeus_ros.bags.errors import BagError
from zeus_ros.bags.kinds import BagLabel, write_label
from zeus_ros.bags.schema import (
    MSGTYPES,
    OFFERED_QOS,
    TOPIC_ACTION,
    TOPIC_CLOCK,
    TOPIC_CONTEXT,
    TOPIC_CONTEXT_TRUTH,
    TOPIC_IMAGE,
    TOPIC_STATE,
    TOPIC_STEP,
    codec,
)

if TYPE_CHECKING:
    from types import TracebackType

    from rosbags.interfaces import Connection, Qos

    from zeus_ros.bags.schema import StepFeedbackFields

__all__ = [
    'BAG_VERSION',
    'ROS_DISTRO',
    'JazzyWriter',
    'QosSource',
    'SimStep',
    'StepBagWriter',
    'Storage',
    'jazzy_metadata',
]

Storage = Literal['mcap', 'sqlite3']
BAG_VERSION: Literal[9] = 9
"""rosbag2 metadata version 9: what Jazzy's rosbag2 writes (QoS profiles as a YAML list)."""
ROS_DISTRO = 'jazzy'
"""metadata.yaml `ros_distro`: rosbag2 writes the distribution that recorded the bag."""
QosSource = Callable[[str], Sequence['Qos']]
"""Gives the QoS profiles offered on a bag topic, asked once, when its first message comes."""

_PLUGINS = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}


def jazzy_metadata(text: str) -> str:
    """The metadata YAML of rosbags with `ros_distro` set as Jazzy's rosbag2 sets it.

    rosbags hard-codes `ros_distro: rosbags`; everything else it writes for version 9 already
    has the fields and layout of Jazzy's rosbag2. Works on metadata.yaml (with the top-level
    `rosbag2_bagfile_information` key) and on the copy embedded in the storage file (without).
    """
    yaml = YAML(typ='safe')
    yaml.default_flow_style = False
    data = yaml.load(text)
    info = data.get('rosbag2_bagfile_information', data)
    info['ros_distro'] = ROS_DISTRO
    out = StringIO()
    yaml.dump(data, out)
    return out.getvalue() if text.endswith('\n') else out.getvalue().strip()


class JazzyWriter(Writer):
    """rosbags' Writer with `ros_distro: jazzy` in metadata.yaml and in the storage file."""

    def close(self) -> None:
        """Close as rosbags does, with the metadata (both copies) saying jazzy."""
        storage = self.storage
        assert storage is not None
        close_storage = storage.close
        storage.close = lambda version, metadata: close_storage(  # type: ignore[method-assign]
            version, jazzy_metadata(metadata))
        super().close()
        self.metapath.write_text(jazzy_metadata(self.metapath.read_text('utf8')), 'utf8')


@dataclass(frozen=True)
class SimStep:
    """What the simulator publishes for control step `step` (one header stamp for all)."""

    step: int
    stamp_ns: int
    state: np.ndarray
    feedback: StepFeedbackFields
    context_names: tuple[str, ...]
    context_values: np.ndarray
    segment: int
    frame: np.ndarray | None = None
    """H x W x 3 uint8, required when the writer records pixels."""


class StepBagWriter:
    """A rosbag2 bag of zeus topics; a context manager that always finalizes the bag.

    On an exception or KeyboardInterrupt inside the `with` block the bag is still closed
    properly (metadata written, sqlite3 transaction committed, mcap footer written), so every
    step written before the interruption stays readable.
    """

    def __init__(self, path: Path | str, *, storage: Storage = 'mcap', pixels: bool,
                 offered_qos: QosSource | None = None, start_ns: int | None = None,
                 label: BagLabel | None = None) -> None:
        """Open the bag; topics are added as their first message arrives.

        `label`: what the bag is (bags/kinds.py), written into its folder as it opens.

        `offered_qos(topic)`: the publishers' QoS profiles (default: what the zeus nodes offer
        in lockstep, as the ROS graph reports them); `start_ns`: the wall-clock time that
        simulation time 0 maps to in bag times (default: now).
        """
        if storage not in _PLUGINS:
            raise ValueError(f'storage must be one of {sorted(_PLUGINS)}, got {storage!r}')
        self.path = Path(path)
        self.storage = storage
        self.pixels = pixels
        self.codec = codec()
        self.counts: dict[str, int] = {}
        self.bytes_written = 0
        self.start_ns = time.time_ns() if start_ns is None else int(start_ns)
        self._offered_qos: QosSource = offered_qos or (lambda topic: OFFERED_QOS[topic])
        self._conns: dict[str, Connection] = {}
        self._writer: Writer | None = None
        try:
            injected_write_fault(self.path)
            writer = JazzyWriter(self.path, version=BAG_VERSION, storage_plugin=_PLUGINS[storage])
            writer.open()
            if label is not None:
                write_label(self.path, label)
        except Exception as exc:  # rosbags raises WriterError, OSError
            raise BagError(self.path, f'cannot create bag: {exc}') from exc
        self._writer = writer
        topics = [TOPIC_CLOCK, TOPIC_STATE, TOPIC_STEP, TOPIC_CONTEXT_TRUTH, TOPIC_ACTION]
        topics += [TOPIC_IMAGE] if pixels else []
        topics.append(TOPIC_CONTEXT)
        self.counts = dict.fromkeys(topics, 0)

    def _connection(self, topic: str) -> Connection:
        """The bag topic, added on its first message with the QoS its publishers offer."""
        conn = self._conns.get(topic)
        if conn is None:
            if topic not in self.counts:
                raise ValueError(
                    f'{self.path}: topic {topic!r} is not recorded by this writer; recorded: '
                    f'{sorted(self.counts)} (pixels={self.pixels})'
                )
            assert self._writer is not None
            conn = self._conns[topic] = self._writer.add_connection(
                topic, MSGTYPES[topic], typestore=self.codec.store,
                offered_qos_profiles=list(self._offered_qos(topic)))
        return conn

    @property
    def closed(self) -> bool:
        """True once the bag is finalized."""
        return self._writer is None

    def write_serialized(self, topic: str, log_ns: int, data: bytes | memoryview) -> None:
        """Write one CDR-serialized message (as received from rclpy) at bag time `log_ns`."""
        if self._writer is None:
            raise BagError(self.path, f'write to {topic} after the bag was closed')
        self._writer.write(self._connection(topic), int(log_ns), data)
        self.counts[topic] += 1
        self.bytes_written += len(data)

    def bag_time(self, sim_ns: int) -> int:
        """Bag time of simulation time `sim_ns`: counted from the run's wall-clock start."""
        return self.start_ns + int(sim_ns)

    def write_step(self, rec: SimStep, *, log_ns: int | None = None) -> None:
        """Write /clock, /zeus/context_truth, the frame, /zeus/step and the state of one step.

        `log_ns` (default: the stamp) is simulation time; the bag stores `bag_time(log_ns)`.
        """
        if self.pixels and rec.frame is None:
            raise ValueError(f'{self.path}: step {rec.step} has no frame but pixels are on')
        if not self.pixels and rec.frame is not None:
            raise ValueError(f'{self.path}: step {rec.step} has a frame but pixels are off')
        log = self.bag_time(rec.stamp_ns if log_ns is None else log_ns)
        c = self.codec
        # The sim_bridge node's publish order: clock, truth, image, feedback, state last.
        self.write_serialized(TOPIC_CLOCK, log, c.serialize(c.clock(rec.stamp_ns)))
        truth = c.truth(rec.step, rec.stamp_ns, rec.context_names, rec.context_values, rec.segment)
        self.write_serialized(TOPIC_CONTEXT_TRUTH, log, c.serialize(truth))
        if rec.frame is not None:
            self.write_serialized(TOPIC_IMAGE, log, c.serialize(c.image(rec.stamp_ns, rec.frame)))
        self.write_serialized(
            TOPIC_STEP, log, c.serialize(c.feedback(rec.step, rec.stamp_ns, rec.feedback))
        )
        self.write_serialized(
            TOPIC_STATE, log, c.serialize(c.state(rec.step, rec.stamp_ns, rec.state))
        )

    def write_action(
        self, step: int, stamp_ns: int, action: np.ndarray, *, log_ns: int | None = None
    ) -> None:
        """Write /zeus/action a_step (the policy's request, before clipping)."""
        log = self.bag_time(stamp_ns if log_ns is None else log_ns)
        msg = self.codec.action(step, stamp_ns, action)
        self.write_serialized(TOPIC_ACTION, log, self.codec.serialize(msg))

    def write_estimate(
        self,
        step: int,
        stamp_ns: int,
        psi: np.ndarray,
        history_length: int,
        *,
        missing_steps: int = 0,
        log_ns: int | None = None,
        checkpoint_sha256: str = '',
    ) -> None:
        """Write /zeus/context psi(H_step)."""
        log = self.bag_time(stamp_ns if log_ns is None else log_ns)
        msg = self.codec.estimate(step, stamp_ns, psi, history_length, missing_steps,
                                  checkpoint_sha256)
        self.write_serialized(TOPIC_CONTEXT, log, self.codec.serialize(msg))

    def close(self) -> None:
        """Finalize the bag (idempotent)."""
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.close()

    def __enter__(self) -> StepBagWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
