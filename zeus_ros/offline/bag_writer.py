"""Write the messages of control steps to a rosbag2 bag (mcap or sqlite3).

Used by `zeus collect` (arrays in) and by the live recorder (CDR bytes from rclpy in). Message
definitions are embedded in the bag (mcap schemas / sqlite3 message_definitions), so `ros2 bag`,
Foxglove or rosbags' AnyReader decode it without this package.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer

from zeus_ros.offline.errors import BagError
from zeus_ros.offline.schema import (
    MSGTYPES,
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

    from rosbags.interfaces import Connection

    from zeus_ros.offline.schema import StepFeedbackFields

__all__ = ['BAG_VERSION', 'StepBagWriter', 'StepRecord', 'Storage']

Storage = Literal['mcap', 'sqlite3']
BAG_VERSION: Literal[8] = 8
"""rosbag2 metadata version 8: what Jazzy's rosbag2 writes and reads."""

_PLUGINS = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}


@dataclass(frozen=True)
class StepRecord:
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

    def __init__(self, path: Path | str, *, storage: Storage = 'mcap', pixels: bool) -> None:
        if storage not in _PLUGINS:
            raise ValueError(f'storage must be one of {sorted(_PLUGINS)}, got {storage!r}')
        self.path = Path(path)
        self.storage = storage
        self.pixels = pixels
        self.codec = codec()
        self.counts: dict[str, int] = {}
        self.bytes_written = 0
        self._conns: dict[str, Connection] = {}
        self._writer: Writer | None = None
        try:
            writer = Writer(self.path, version=BAG_VERSION, storage_plugin=_PLUGINS[storage])
            writer.open()
        except Exception as exc:  # rosbags raises WriterError, OSError
            raise BagError(self.path, f'cannot create bag: {exc}') from exc
        self._writer = writer
        topics = [TOPIC_CLOCK, TOPIC_STATE, TOPIC_STEP, TOPIC_CONTEXT_TRUTH, TOPIC_ACTION]
        topics += [TOPIC_IMAGE] if pixels else []
        topics.append(TOPIC_CONTEXT)
        for topic in topics:
            self._conns[topic] = self._writer.add_connection(
                topic, MSGTYPES[topic], typestore=self.codec.store
            )
            self.counts[topic] = 0

    @property
    def closed(self) -> bool:
        """True once the bag is finalized."""
        return self._writer is None

    def write_serialized(self, topic: str, log_ns: int, data: bytes | memoryview) -> None:
        """Write one CDR-serialized message (as received from rclpy) at bag time `log_ns`."""
        if self._writer is None:
            raise BagError(self.path, f'write to {topic} after the bag was closed')
        conn = self._conns.get(topic)
        if conn is None:
            raise ValueError(
                f'{self.path}: topic {topic!r} is not recorded by this writer; recorded: '
                f'{sorted(self._conns)} (pixels={self.pixels})'
            )
        self._writer.write(conn, int(log_ns), data)
        self.counts[topic] += 1
        self.bytes_written += len(data)

    def write_step(self, rec: StepRecord, *, log_ns: int | None = None) -> None:
        """Write /clock, /zeus/context_truth, the frame, /zeus/step and the state of one step."""
        if self.pixels and rec.frame is None:
            raise ValueError(f'{self.path}: step {rec.step} has no frame but pixels are on')
        if not self.pixels and rec.frame is not None:
            raise ValueError(f'{self.path}: step {rec.step} has a frame but pixels are off')
        log = rec.stamp_ns if log_ns is None else log_ns
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
        log = stamp_ns if log_ns is None else log_ns
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
    ) -> None:
        """Write /zeus/context psi(H_step)."""
        log = stamp_ns if log_ns is None else log_ns
        msg = self.codec.estimate(step, stamp_ns, psi, history_length, missing_steps)
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
