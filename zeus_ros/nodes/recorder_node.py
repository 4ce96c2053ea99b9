"""recorder node: the zeus topics as CDR bytes into rosbag2 bags that survive a crash.

Messages are taken raw (no deserialization) and written through the same bag schema as
`zeus collect`, so both kinds of bag ingest identically. Every `flush_period_s` the bag is made
crash-safe (mcap chunk out / sqlite3 commit, provisional metadata.yaml): after a SIGKILL,
`zeus recover` restores everything but the last flush period. SIGINT / SIGTERM close the bag
properly. Counts, step gaps (drops), bytes and flushes are on /diagnostics while recording.

Logging never stops control: a bag that cannot be written (disk full, permission denied, a
read-only or vanished folder) is an ERROR on the log and /diagnostics, the node keeps running,
drops the bag (what it flushed stays recoverable) and tries a new one with back-off
(`retry_s` doubling to `retry_max_s`). The steps it could not record are counted and named, as
ranges, on /diagnostics and in its closing line ("not recorded: steps ...").
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from functools import partial
import importlib
from pathlib import Path
import shutil
import sqlite3
import time
from typing import TYPE_CHECKING, Any, cast

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from zeus_ros.bags.durable import DurableBagWriter
from zeus_ros.bags.errors import BagError
from zeus_ros.bags.kinds import BagLabel
from zeus_ros.bags.recover import STEP_TOPICS, stamp_from_cdr, step_from_cdr
from zeus_ros.bags.schema import MSGTYPES, OFFERED_QOS, TOPIC_IMAGE, TOPIC_STEP
from zeus_ros.nodes.messages import diagnostics_message
from zeus_ros.nodes.params import Spec, declare_specs, serve_live_changes
from zeus_ros.nodes.peers import call_when_ready, steady_timer, unmatched_readers
from zeus_ros.nodes.spin import run_node
from zeus_ros.nodes.topics import TOPICS, step_qos
from zeus_ros.nodes.unrecorded import Unrecorded

if TYPE_CHECKING:
    from rclpy.duration import Duration

    from zeus_ros.bags.writer import Storage

STORAGES = ('mcap', 'sqlite3')
MAX_FLUSH_PERIOD_S = 60.0
SPECS: dict[str, Spec] = {
    'output': Spec('', "directory of the bags; '' = ./bags/zeus_<date>_<time>"),
    'storage': Spec('mcap', 'bag storage', choices=STORAGES),
    'topics': Spec(list(MSGTYPES), 'zeus schema topics to record (bag names; a zeus topic is '
                   "subscribed relative to the recorder's namespace)"),
    'split_size_mb': Spec(0.0, 'start a new bag at this many MB (0: never)', live=True,
                          low=0.0),
    'split_duration_s': Spec(0.0, 'start a new bag after this many seconds (0: never)',
                             live=True, low=0.0),
    'flush_period_s': Spec(1.0, 'seconds between flushes; bounds what a crash loses',
                           low=0.001, high=MAX_FLUSH_PERIOD_S),
    'image_best_effort': Spec(False, 'subscribe to frames best effort (realtime only)'),
    'expected_publishers': Spec([''], 'recorded topics (bag names) whose publishers must be '
                                'matched before the recorder subscribes to /zeus/step, which '
                                "lets the loop start: a bag then holds them from step 0 "
                                "(launchers set it; '': none)"),
    'publisher_timeout': Spec(20.0, 'seconds to wait for expected_publishers; then log what is '
                              'short and subscribe to the steps anyway', low=0.0),
    'retry_s': Spec(1.0, 'first wait before a new bag after a write failed (disk full, '
                    'permission); doubles per failed try', low=0.05, high=MAX_FLUSH_PERIOD_S),
    'kind': Spec('manual', 'what its bags are, written into each (zeus bags lists them, zeus '
                 'train --bags chooses by kind): manual, or continual (launch --continual)',
                 choices=('manual', 'continual')),
    'label_task': Spec('', "the task named in each bag's label (launchers set it)"),
    'label_checkpoint': Spec('', "the checkpoint named in each bag's label: the one deployed "
                             'when the recording started (launchers set it)'),
    'retry_max_s': Spec(30.0, 'longest wait between tries of a new bag', low=0.05,
                        high=3600.0),
}
WRITE_ERRORS = (OSError, BagError, sqlite3.Error)
"""What a bag write raises when the disk or folder fails us (sqlite3: 'database or disk is
full'); anything else is a bug and ends the node."""
RECORD_DEPTH = 1000
"""Reliable keep-last depth: what arrives while the recorder is held up (a slow flush, no CPU
on a busy machine) waits here; with 100, a fast lockstep loop (a few hundred steps/s in one
process) overflowed it in a fraction of a second and the bag had gaps."""
SPLIT_GRACE_S = 1.0
"""After a split the previous bag stays open this long for late messages of its own steps."""
RECENT_STAMPS = 256
DRAIN_QUIET_S = 0.3
"""After Ctrl-C / SIGTERM: record on until no message came for this long (what was in flight)."""


def _message_class(msgtype: str) -> type:
    """The rclpy class of 'pkg/msg/Name' (the wheel install has no rosidl_runtime_py)."""
    package, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def _qos_time(duration: Duration) -> QosTime:
    sec, nsec = divmod(duration.nanoseconds, 1_000_000_000)
    return QosTime(sec=sec, nsec=nsec)


def bag_qos(profile: QoSProfile) -> Qos:
    """A publisher's QoS from the ROS graph in the form metadata.yaml stores (as rosbag2 does)."""
    return Qos(
        history=QosHistory(int(profile.history)), depth=int(profile.depth),
        reliability=QosReliability(int(profile.reliability)),
        durability=QosDurability(int(profile.durability)),
        deadline=_qos_time(profile.deadline), lifespan=_qos_time(profile.lifespan),
        liveliness=QosLiveliness(int(profile.liveliness)),
        liveliness_lease_duration=_qos_time(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions))


@dataclass
class _Closing:
    """A bag before a split: it takes late messages of steps first..boundary-1 until deadline."""

    writer: DurableBagWriter
    first: int
    boundary: int
    deadline: float


class RecorderNode(Node):
    """Records the zeus topics to split, crash-safe bags and reports drops live."""

    def __init__(self, **node_options: Any) -> None:
        """`node_options` go to rclpy's Node (cli_args, context): one process can hold several."""
        super().__init__('recorder', **node_options)
        self.params = self._read_parameters()
        self.output = Path(self.params['output']).expanduser().resolve()
        if not self.params['output']:  # like rosbag2: a new timestamped directory
            self.output = Path('bags').resolve() / time.strftime('zeus_%Y%m%d_%H%M%S')
        self.storage: str = self.params['storage']
        self.topics: list[str] = list(self.params['topics'])
        self.exit_code = 0
        self.counts = dict.fromkeys(self.topics, 0)
        self.gaps = dict.fromkeys(self.topics, 0)
        self.last_step: dict[str, int] = {}
        self.bags: list[Path] = []
        self.bytes_written = 0
        self.flushes = 0
        self._writer: DurableBagWriter | None = None
        self._closing: list[_Closing] = []
        self._first_step = -1
        """Lowest step of the bag being written (the boundary of the last split)."""
        self._recent: OrderedDict[int, int] = OrderedDict()
        """stamp -> step of recent steps: routes /clock and images, which carry no step."""
        self._opened = time.monotonic()
        self._sources: dict[str, str] = {}
        """bag topic -> the name subscribed (relative: follows namespace and remaps)."""
        self.unrecorded = Unrecorded(self.params['retry_s'], self.params['retry_max_s'])
        self._heard_step = -1
        """Highest step heard (written or not): where a range of unrecorded steps ends."""
        self._flushed_step = -1
        """Highest step heard at the last flush that succeeded: everything up to it is on disk."""

        # zeus/step last: a step producer that sees this subscription (min_observers) knows the
        # others exist, and it waits until its own publishers have matched them; this node
        # makes it only once its own readers have matched the expected publishers (step 0 kept
        # on both sides of every match).
        self._readers = {topic: self._subscribe(topic) for topic in self.topics
                         if topic != TOPIC_STEP}
        self._start_first_bag()  # a start-up failure above leaves no empty bag behind
        if TOPIC_STEP in self.topics and self.params['expected_publishers']:
            self._subscribe_steps_when_heard()
        elif TOPIC_STEP in self.topics:  # by hand: from whatever step it first hears
            self._readers[TOPIC_STEP] = self._subscribe(TOPIC_STEP)
        self._pub_diag = self.create_publisher(DiagnosticArray, TOPICS.DIAGNOSTICS, 10)
        steady_timer(self, self.params['flush_period_s'], self._on_flush_timer)
        steady_timer(self, 1.0, self._publish_diagnostics)
        serve_live_changes(self, SPECS, self.params, lambda _changed: None)
        self.get_logger().info(
            f'recording {len(self.topics)} topics to {self.output} ({self.storage}), flush every '
            f'{self.params["flush_period_s"]} s, split at {self.params["split_size_mb"]} MB / '
            f'{self.params["split_duration_s"]} s (0: never)'
        )
        if self.get_namespace() != '/':
            self.get_logger().info(f'zeus topics of namespace {self.get_namespace()} are written '
                                   'under their schema names (/zeus/...), so ingest reads them')

    def _subscribe(self, topic: str) -> Any:
        qos = step_qos(RECORD_DEPTH)
        if topic == TOPIC_IMAGE and self.params['image_best_effort']:
            qos = qos_profile_sensor_data  # realtime frames: a late frame is worth nothing
        # The bag keeps the schema name; the subscription follows namespace and remaps.
        source = self._sources[topic] = topic if topic == TOPICS.CLOCK else topic.lstrip('/')
        return self.create_subscription(
            _message_class(MSGTYPES[topic]), source, partial(self._on_message, topic), qos,
            raw=True)

    def _subscribe_steps_when_heard(self) -> None:
        """Subscribe to /zeus/step once the expected publishers are matched (or on timeout)."""
        def subscribe_steps() -> None:
            self._readers[TOPIC_STEP] = self._subscribe(TOPIC_STEP)

        call_when_ready(self, self._unheard, subscribe_steps, self.params['publisher_timeout'],
                        'publisher_timeout', 'subscribing to the steps anyway: the bag may miss '
                        'the first steps of these topics')

    def _unheard(self) -> list[str]:
        """What _subscribe_steps_when_heard still waits for (empty: subscribe now)."""
        expected = self.params['expected_publishers']
        return unmatched_readers(self, [(reader, int(topic in expected))
                                        for topic, reader in self._readers.items()],
                                 sources=[TOPIC_STEP] if TOPIC_STEP in expected else [])

    # -- parameters -------------------------------------------------------------------------
    def _read_parameters(self) -> dict[str, Any]:
        """Declare every parameter with its default, then validate them all with clear errors."""
        params = declare_specs(self, SPECS)
        params['topics'] = self._check_topics(params['topics'])
        params['expected_publishers'] = [t for t in params['expected_publishers'] if t]
        unknown = sorted(set(params['expected_publishers']) - set(params['topics']))
        if unknown:
            raise ValueError(f'recorder: parameter expected_publishers names {unknown}, which '
                             f'it does not record; recorded: {", ".join(params["topics"])}')
        self._check_output(params['output'])
        return params

    @staticmethod
    def _check_topics(topics: Any) -> list[str]:
        if isinstance(topics, str) or not topics or not all(isinstance(t, str) for t in topics):
            raise ValueError(f'recorder: parameter topics must be a non-empty list of topic '
                             f'names, got {topics!r}')
        bad = [t for t in topics if t not in MSGTYPES]
        if bad:
            raise ValueError(f'recorder: parameter topics has unknown topic(s) {bad}; '
                             f'allowed: {", ".join(MSGTYPES)}')
        if len(set(topics)) != len(topics):
            raise ValueError(f'recorder: parameter topics lists a topic twice: {list(topics)}')
        return list(topics)

    @staticmethod
    def _check_output(output: Any) -> None:
        if not isinstance(output, str):
            raise ValueError(f'recorder: parameter output must be a directory path, got '
                             f'{output!r}')
        path = Path(output).expanduser()
        if output and path.exists() and (not path.is_dir() or any(path.iterdir())):
            raise ValueError(f'recorder: parameter output={output!r} exists and is not an empty '
                             'directory; choose a new one (bags are never overwritten)')

    # -- recording --------------------------------------------------------------------------
    def _start_first_bag(self) -> None:
        """The first bag; a folder that cannot be written is a write failure, not bad params."""
        try:
            self._open_next_bag()
        except WRITE_ERRORS as exc:
            self._fail(exc)

    def _open_next_bag(self) -> None:
        """Start bag OUTPUT/<name>_<NNN> (NNN counts splits and retries from 000).

        Raises what the disk raises (WRITE_ERRORS); a bag folder it half made is removed.
        """
        path = self.output / f'{self.output.name}_{len(self.bags):03d}'
        try:
            self.output.mkdir(parents=True, exist_ok=True)
            self._writer = DurableBagWriter(
                path, storage=cast('Storage', self.storage), pixels=TOPIC_IMAGE in self.topics,
                offered_qos=self._offered_qos, label=BagLabel(
                    self.params['kind'], task=self.params['label_task'],
                    checkpoint=self.params['label_checkpoint']))
        except WRITE_ERRORS:
            shutil.rmtree(path, ignore_errors=True)
            raise
        self.bags.append(path)
        self._opened = time.monotonic()
        if len(self.bags) > 1:
            self.get_logger().info(f'split: now writing {path}')

    def _offered_qos(self, topic: str) -> list[Qos]:
        """What the publishers of a bag topic offer, from the graph, for `ros2 bag play`.

        Asked when the topic's first message arrives, so its publisher is known by then.
        """
        infos = self.get_publishers_info_by_topic(self.resolve_topic_name(self._sources[topic]))
        return [bag_qos(info.qos_profile) for info in infos] or list(OFFERED_QOS[topic])

    def _split(self) -> None:
        """Open the next bag; the old one keeps taking late messages of its steps a moment."""
        assert self._writer is not None
        old = self._writer
        boundary = max(max(self.last_step.values(), default=-1) + 1, self._first_step)
        self._open_next_bag()
        self._closing.append(
            _Closing(old, self._first_step, boundary, time.monotonic() + SPLIT_GRACE_S))
        self._first_step = boundary

    def _close_old(self, now: float | None = None) -> None:
        """Close the split-off bags whose grace is over (all of them without `now`)."""
        for closing in list(self._closing):
            if now is None or now >= closing.deadline:
                closing.writer.close()
                self.flushes += closing.writer.flushes
                self._closing.remove(closing)
            else:
                closing.writer.flush()

    def _on_message(self, topic: str, data: bytes) -> None:
        """Write one serialized message; count it and the steps it skipped.

        While no bag can be written, the message is dropped and its step noted as unrecorded.
        """
        step = step_from_cdr(data) if topic in STEP_TOPICS else None
        if step is not None:
            self._heard_step = max(self._heard_step, step)
        if self._writer is None:  # failing: the loop goes on, this step is in no bag
            if step is not None:
                self.unrecorded.note(step)
                self.last_step[topic] = step  # named as unrecorded, not as a drop upstream
            return
        try:
            self._write(topic, data, step)
        except WRITE_ERRORS as exc:
            self._fail(exc)

    def _write(self, topic: str, data: bytes, step: int | None) -> None:
        stamp = stamp_from_cdr(data)
        if step is not None and stamp is not None:
            self._recent[stamp] = step
            if len(self._recent) > RECENT_STAMPS:
                self._recent.popitem(last=False)
        writer = self._writer
        of_step = step if step is not None else self._recent.get(stamp, None)
        if of_step is not None:  # a split never cuts a step: all its messages go together
            for closing in self._closing:
                if closing.first <= of_step < closing.boundary:
                    writer = closing.writer
        assert writer is not None
        writer.write_serialized(topic, time.time_ns(), data)
        self.counts[topic] += 1
        self.bytes_written += len(data)
        if step is not None:
            self._track_step(topic, step)
        limit = self.params['split_size_mb'] * 1e6
        if limit and writer is self._writer and writer.bytes_written >= limit:
            self._split()

    @property
    def received(self) -> int:
        """Messages written so far (run_node's drain watches it)."""
        return sum(self.counts.values())

    def _track_step(self, topic: str, step: int) -> None:
        last = self.last_step.get(topic)
        if last is None:  # says when recording really starts (discovery takes a while)
            self.get_logger().info(f'{topic}: first message at step {step}')
        if last is not None and step > last + 1:
            missing = step - last - 1
            self.gaps[topic] += missing
            self.get_logger().warning(
                f'{topic}: {missing} step(s) missing before step {step} (dropped upstream or '
                'by DDS)', throttle_duration_sec=2.0)
        self.last_step[topic] = step  # a smaller step means a restarted simulator: follow it

    def _on_flush_timer(self) -> None:
        """Make the bags crash-safe; close a split-off bag after its grace; split by duration.

        While failing: try a new bag when the back-off is over.
        """
        now = time.monotonic()
        if self._writer is None:
            self._retry(now)
            return
        heard = self._heard_step
        try:
            self._writer.flush()
            self._close_old(now)
            duration = self.params['split_duration_s']
            if duration and now - self._opened >= duration:
                self._split()
        except WRITE_ERRORS as exc:
            self._fail(exc)
            return
        self._flushed_step = heard

    def _fail(self, exc: BaseException) -> None:
        """A bag write failed: ERROR, let go of every open bag, the next try after a back-off.

        The steps since the last flush that succeeded are counted as unrecorded (a recovered
        bag may hold a few of them); the node keeps running and never stops the loop.
        """
        bag = self.bags[-1] if self.bags and self._writer is not None else None
        for writer in [c.writer for c in self._closing] + [self._writer]:
            if writer is not None:
                self.flushes += writer.flushes
                writer.abandon()
        self._closing.clear()
        self._writer = None
        heard = self._heard_step if self._heard_step > self._flushed_step else None
        self.unrecorded.fail(str(exc), time.monotonic(), self._flushed_step + 1, heard)
        kept = f'; `zeus recover {bag}` closes what it flushed' if bag else ''
        self.get_logger().error(
            f'cannot write {bag or self.output}: {exc}; the control loop is not affected, the '
            f'steps from {self._flushed_step + 1} (the last flush) on are not recorded{kept}; '
            'trying a new bag '
            f'every {self.unrecorded.wait_s:g} s or more (at most {self.unrecorded.max_s:g} s)')

    def _retry(self, now: float) -> None:
        """Try a new bag once the back-off is over; say when recording goes on."""
        if not self.unrecorded.retry_due(now):
            return
        try:
            self._open_next_bag()
        except WRITE_ERRORS as exc:
            self.unrecorded.retry_failed(str(exc), now)
            self.get_logger().error(
                f'still cannot write {self.output}: {exc}; next try in '
                f'{self.unrecorded.wait_s:g} s', throttle_duration_sec=10.0)
            return
        lost = self.unrecorded.recovered()
        self._flushed_step = self._heard_step
        self._first_step = self._heard_step + 1
        self.get_logger().warning(
            f'recording again into {self.bags[-1]}; not recorded so far: steps {lost} '
            f'({self.unrecorded.steps} steps)')

    def _publish_diagnostics(self) -> None:
        open_writers = [c.writer for c in self._closing]
        open_writers += [self._writer] if self._writer else []
        flushes = self.flushes + sum(w.flushes for w in open_writers)
        values: dict[str, object] = {
            'bag': self.bags[-1] if self.bags else '', 'storage': self.storage,
            'bags': len(self.bags), 'bytes_written': self.bytes_written, 'flushes': flushes,
        }
        for topic in self.topics:
            values[f'messages {topic}'] = self.counts[topic]
            if topic in STEP_TOPICS:
                values[f'gaps {topic}'] = self.gaps[topic]
                values[f'last_step {topic}'] = self.last_step.get(topic, '')
        problems = [f'{n} steps missing on {t}' for t, n in self.gaps.items() if n]
        values['unrecorded steps'] = self.unrecorded.steps
        values['unrecorded'] = self.unrecorded.summary()
        values['write failures'] = self.unrecorded.failures
        errors = [f'cannot write bags ({self.unrecorded.error}): {self.unrecorded.summary()} not '
                  f'recorded so far, next try in '
                  f'{max(0.0, self.unrecorded.retry_at - time.monotonic()):.1f} s'
                  ] if self.unrecorded.failing else []
        try:
            self._pub_diag.publish(diagnostics_message(self, 'bag', values, problems, errors))
        except Exception:  # rclpy's RCLError when SIGTERM shut the context down mid-callback
            if self.context.ok():
                raise

    def close(self) -> None:
        """Finalize the open bag (mcap footer, final metadata.yaml) and log the totals.

        Steps that no bag holds (write failures) are named on a line of their own, which
        `zeus launch` reports among the recording's gaps.
        """
        try:
            self._close_old()
            if self._writer is not None:
                self._writer.close()
                self.flushes += self._writer.flushes
        except WRITE_ERRORS as exc:  # the disk failed at the very end: the bag stays provisional
            self._fail(exc)
        self._writer = None
        gaps = {t: n for t, n in self.gaps.items() if n}
        self.get_logger().info(
            f'closed {len(self.bags)} bag(s) in {self.output}: {sum(self.counts.values())} '
            f'messages, {self.bytes_written} bytes, {self.flushes} flushes, '
            f'step gaps {gaps or "none"}'
        )
        if self.unrecorded.ranges:
            self.get_logger().error(
                f'not recorded: {self.unrecorded.summary()} ({self.unrecorded.failures} write '
                f'failure(s), last: {self.unrecorded.error or "recovered"})')


def main(args: list[str] | None = None) -> int:
    """Entry point of `ros2 run zeus_ros recorder_node`."""
    return run_node(RecorderNode, args, drain=DRAIN_QUIET_S)


if __name__ == '__main__':
    raise SystemExit(main())
