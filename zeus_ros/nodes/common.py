"""What every zeus_ros node shares: topic names, QoS decisions, stamps, conversions, main()."""

from __future__ import annotations

from collections.abc import Callable, Sequence
import faulthandler
import math
import os
from pathlib import Path
import signal
import sys
import time
from typing import TYPE_CHECKING, Any, NoReturn

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import (
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import Image

from zeus_ros.nodes.shutdown import bounded, start_stop_limit

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.timer import Timer

__all__ = [
    'EXECUTORS',
    'EXECUTOR_ENV',
    'TOPICS',
    'NodeFinished',
    'WaitReport',
    'action_qos',
    'array_from_image',
    'call_when_ready',
    'count_publishers',
    'count_subscribers',
    'diagnostics_message',
    'executor_kind',
    'image_from_array',
    'image_qos',
    'make_executor',
    'missing_peers',
    'publisher_qos',
    'run_node',
    'run_nodes',
    'seconds_from_stamp',
    'stamp_from_seconds',
    'stamp_ns',
    'steady_timer',
    'step_qos',
]


class TOPICS:
    """Topic names of the step protocol (DESIGN.md section 1); one place for all nodes.

    The zeus topics are relative, so `__ns:=/robot1` moves a whole system and `-r` remaps them;
    /clock and /diagnostics stay absolute, as ROS convention wants (one clock, one aggregator).
    """

    STATE = 'zeus/observation/state'
    IMAGE = 'zeus/observation/image'
    STEP = 'zeus/step'
    CONTEXT_TRUTH = 'zeus/context_truth'
    CONTEXT = 'zeus/context'
    CONTEXT_READOUT = 'zeus/context_readout'
    """ContextTruth-typed: the estimate in the context's units (the checkpoint's read-out)."""
    CONTEXT_NOVELTY = 'zeus/context_novelty'
    """ContextTruth-typed: names novelty, threshold, novel (1.0 outside the training contexts)."""
    ACTION = 'zeus/action'
    CLOCK = '/clock'
    DIAGNOSTICS = '/diagnostics'


def steady_timer(node: Node, period: float, callback: Callable[[], None]) -> Timer:
    """A timer on the steady clock: it runs before /clock moves, even with use_sim_time."""
    return node.create_timer(period, callback, clock=Clock(clock_type=ClockType.STEADY_TIME))


def count_publishers(node: Node, topic: str) -> int:
    """Publishers on `topic` as this node resolves it (namespace and remaps applied)."""
    return node.count_publishers(node.resolve_topic_name(topic))


def count_subscribers(node: Node, topic: str) -> int:
    """Subscribers on `topic` as this node resolves it (namespace and remaps applied)."""
    return node.count_subscribers(node.resolve_topic_name(topic))


class WaitReport:
    """Says what a start-up wait is waiting for, once it has lasted `after` seconds.

    Quiet for a normal start; a wait that never ends (a remapped or missing peer) then names
    the resolved topic and what is missing, every `every` seconds.
    """

    def __init__(self, node: Node, after: float = 3.0, every: float = 10.0) -> None:
        self._node = node
        self._start = time.monotonic()
        self._after = after
        self._every = every
        self._last = -math.inf

    def waiting(self, what: str) -> None:
        """Log `what` if this wait has lasted long enough and nothing was said recently."""
        now = time.monotonic()
        if now - self._start >= self._after and now - self._last >= self._every:
            self._last = now
            self._node.get_logger().warning(
                f'still waiting after {now - self._start:.0f} s: {what}')


def call_when_ready(node: Node, short_of: Callable[[], list[str]], then: Callable[[], None],
                    timeout: float, timeout_name: str, consequence: str) -> None:
    """Call `then` once `short_of()` names nothing, or after `timeout` seconds in any case.

    The one start-up gate of the nodes that give the loop its go-ahead by subscribing to the
    steps (estimator, policy, recorder): polled on the steady clock (no busy wait, runs before
    /clock moves), quiet for a normal start, then naming what is short (WaitReport); on
    timeout it warns with the parameter's name and what the late start may cost.
    """
    if not short_of():
        then()
        return
    deadline = time.monotonic() + timeout
    report = WaitReport(node)

    def poll() -> None:
        short = short_of()
        if short and time.monotonic() < deadline:
            report.waiting('; '.join(short))
            return
        if short:
            node.get_logger().warning(f'{timeout_name}: {timeout:g} s passed waiting for '
                                      f'{"; ".join(short)}; {consequence}')
        timer.cancel()
        node.destroy_timer(timer)
        then()

    timer = steady_timer(node, 0.05, poll)


def missing_peers(node: Node, outputs: Sequence[Any], action_sub: Any, min_observers: int,
                  others: Sequence[Any] = (), named: Sequence[str] = ()) -> list[str]:
    """What a step producer still waits for before step 0 (empty: start).

    `outputs` are its publishers, the StepFeedback one first, then the observations; `others`
    its further per-step publishers (true context, /clock), which only need every discovered
    subscriber matched. Graph counts say who was discovered; the matched counts of our own
    endpoints say whose data path is ready. Starting before they agree would drop step 0 for a
    late peer (the estimator would miss it and the policy would act on no context; a recorder
    would miss it in the bag). `min_observers` names how many step subscribers a launch
    expects (estimator, policy, recorder, ...), so a peer that is still starting up is waited
    for rather than missed; a recorder subscribes to the steps last, so once it counts here its
    other subscriptions are known too. `named` (parameter `observers`) names the nodes that
    must be among the step subscribers (a launcher's group): a count alone can be met by a
    bystander (a status line, `ros2 topic echo`) while a node of the group is still starting.
    Counted on the names as the node resolved them: namespace and remaps applied.
    """
    step_pub, observations = outputs[0], outputs[1:]
    observers = sum(node.count_subscribers(pub.topic_name) for pub in observations)
    unmatched = [pub.topic_name for pub in (*outputs, *others)
                 if pub.get_subscription_count() < node.count_subscribers(pub.topic_name)]
    action_topic = action_sub.topic_name
    actions = node.count_publishers(action_topic)
    listening = step_pub.get_subscription_count()
    missing = []
    if actions == 0:
        missing.append(f'a policy publishing on {action_topic}')
    if observers == 0:
        missing.append(f'a subscriber of {observations[0].topic_name}')
    if listening < min_observers:
        missing.append(f'{min_observers} subscribers of {step_pub.topic_name} (min_observers; '
                       f'{listening} so far)')
    named = [name for name in named if name]  # the parameter's empty default: [''] (any)
    if named:
        present = {info.node_name
                   for info in node.get_subscriptions_info_by_topic(step_pub.topic_name)}
        absent = [name for name in named if name not in present]
        if absent:
            missing.append(f'{", ".join(absent)} subscribed to {step_pub.topic_name} '
                           '(observers)')
    if unmatched or action_sub.get_publisher_count() < actions:
        missing.append(f'DDS to match the endpoints of {unmatched or [action_topic]}')
    return missing


def unmatched_readers(node: Node, readers: Sequence[tuple[Any, int]],
                      sources: Sequence[str] = ()) -> list[str]:
    """Which of this node's `(subscription, expected publishers)` cannot hear them all yet.

    The start gates above count what the *writer* matched; a reader matches the writer on its
    own side when its participant processes the writer's announcement, which on a loaded
    machine can come later, and a volatile reader drops what arrives before that. A node that
    gives the loop its go-ahead (subscribes to the steps) only once these readers have matched
    every publisher the graph shows (and at least `expected`) loses nothing at step 0; a
    reader created after its publishers were discovered matches them at once. With `sources`
    (topics, relative or absolute: resolved in the node's namespace; the steps, and for a
    node that acts on them the observations) it is also short while one of them has no
    publisher discovered: a node that waits for the step source (estimator, policy, recorder,
    viewer) then subscribes to a source it matches at once.
    """
    short = []
    for reader, expected in readers:
        needed = max(expected, node.count_publishers(reader.topic_name))
        matched = reader.get_publisher_count()
        if matched < needed:
            short.append(f'{reader.topic_name} ({matched} of {needed} publishers matched)')
    resolved = [node.resolve_topic_name(topic.lstrip('/')) for topic in sources]
    unseen = [topic for topic in resolved if node.count_publishers(topic) == 0]
    if unseen:
        short.append(f'a publisher of {" and of ".join(unseen)}')
    return short


def step_qos(depth: int = 10) -> QoSProfile:
    """Reliable keep-last: in lockstep no step may silently vanish (a loss shows as a gap)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE
    )


STEP_BACKLOG = 1000
"""History depth of a lockstep publisher. A reliable reader that misses messages (a recorder
starved of CPU on a busy machine: its transport queue overflows) gets them resent when DDS
notices the loss, which can take a good part of a second; at a few hundred steps/s a history
of 10 was overwritten by then and the bag had gaps. The recorder's reader history is as deep
(RECORD_DEPTH). Small messages: a few hundred KiB per topic at most."""


def publisher_qos(mode: str) -> QoSProfile:
    """Step-protocol publishers: reliable, with a STEP_BACKLOG-deep history in lockstep."""
    return step_qos(STEP_BACKLOG) if mode == 'lockstep' else step_qos()


def image_qos(mode: str) -> QoSProfile:
    """Frames: reliable in lockstep (every step counts); sensor-data (best effort) in realtime."""
    return step_qos() if mode == 'lockstep' else qos_profile_sensor_data


def action_qos(mode: str) -> QoSProfile:
    """Actions: reliable; in realtime only the newest matters (depth 1, zero-order hold)."""
    return publisher_qos(mode) if mode == 'lockstep' else step_qos(depth=1)


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

    `problems` are faults the node covers and counts; `errors` need someone to act.
    """
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


class NodeFinished(Exception):  # noqa: N818 - a signal, not an error
    """Raised from a callback when a node has done its job (e.g. max_steps reached).

    Setting the node's `finished` attribute to True does the same without raising: the events
    executor logs every exception a callback raises as FATAL before passing it on.
    """


def _exit_now(code: int) -> NoReturn:
    """Leave without Python's interpreter teardown, which adds about a second with torch.

    Everything is closed and flushed by now (bags, node, ROS logging), so nothing is lost.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _deliver_published(nodes: Sequence[Node], timeout: float = 2.0) -> None:
    """A node finished its job: let reliable readers (a recorder) take what it last published.

    Destroying a publisher drops what its readers have not acknowledged yet; a recorder that
    runs a little behind would lose the last steps of a run. Waits `timeout` seconds at most.
    """
    from rclpy.duration import Duration

    deadline = time.monotonic() + timeout
    for node in nodes:
        for publisher in node.publishers:
            left = deadline - time.monotonic()
            if left <= 0:
                return
            if publisher.qos_profile.reliability == ReliabilityPolicy.RELIABLE:
                publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))


STACKS_SIGNAL = signal.SIGUSR1
"""The signal on which a node process prints every thread's stack to stderr and goes on."""
DRAIN_LIMIT_S = 2.0
"""The longest a draining node goes on taking messages after a stop signal."""
STOP_DELIVERY_S = 1.5
"""The longest a node stopped by a signal waits for its reliable readers to take its last
messages (a finished node waits 2 s: nothing else is stopping it). Usually they have: no wait.
With 0.5 a recorder starved of CPU on an overloaded machine was 0.6 s (150 steps of the
one-process loop) behind at Ctrl-C and lost them; the recorder drains for DRAIN_LIMIT_S."""


def run_node(factory: Callable[[], Node], args: list[str] | None = None, drain: float = 0.0
             ) -> NoReturn:
    """Jazzy shutdown pattern: spin until Ctrl-C / SIGTERM / external shutdown, then clean up.

    A `ValueError` raised while building the node (bad parameters) is printed as one clear line
    and gives exit code 2, instead of a traceback. A signal ends the spin, `close()` runs to its
    end, and the process exits 0 (or the node's `exit_code`). With `drain` (a recorder) the
    node first takes what is still queued for it (see `_drain`); any other node first lets its
    reliable readers take what it published last (`_deliver_published`).
    """
    run_nodes([factory], args, drain)


EXECUTOR_ENV = 'ZEUS_EXECUTOR'
"""The environment variable that chooses the executor every node process spins on."""
EXECUTORS = ('events', 'single')
"""events: rclpy.experimental.EventsExecutor (rcl's event callbacks, dispatched in C++);
single: rclpy's SingleThreadedExecutor (a wait set rebuilt in Python per turn). The first is
the default: the three-node state loop measured 1.2-1.6x the steps/s on 25-40 % less CPU per
step as processes (benchmarks/bench_live_loop.py --executors single,events; README)."""


def executor_kind() -> str:
    """The executor `$ZEUS_EXECUTOR` names (EXECUTORS; unset or empty: the default).

    Raises ValueError (one line naming the variable, the value and the choices) for anything
    else.
    """
    kind = os.environ.get(EXECUTOR_ENV, '').strip().lower() or EXECUTORS[0]
    if kind not in EXECUTORS:
        raise ValueError(f'{EXECUTOR_ENV}={os.environ[EXECUTOR_ENV]!r}: unknown executor; '
                         f'choose from {", ".join(EXECUTORS)}')
    return kind


def _run_in_place(coroutine: Any) -> Any:
    """Run a coroutine that never suspends to its end, without an event loop.

    What the events executor runs a waitable's `execute()` with, in place of `asyncio.run`,
    which builds and closes an event loop per call (~0.1 ms, twice per lockstep step: sim_bridge's
    actions and the policy's contexts come through `SenderSubscription`s). The waitables of our
    nodes (SenderSubscription, rclpy's QoS event handlers on plain callbacks) never suspend;
    one that does is closed and reported, never left half-run.
    """
    try:
        coroutine.send(None)
    except StopIteration as done:
        return done.value
    coroutine.close()
    raise RuntimeError(f'{coroutine!r} waits on something: the events executor of zeus_ros '
                       'nodes runs waitables without an event loop (ZEUS_EXECUTOR=single does)')


def _events_executor(context: Context | None) -> Executor:
    """The EventsExecutor of rclpy, running waitables with `_run_in_place`.

    It looks `asyncio.run` up once, when it is built: only this executor runs without it.
    """
    import asyncio

    from rclpy.experimental import EventsExecutor

    run = asyncio.run
    asyncio.run = _run_in_place
    try:
        return EventsExecutor(context=context)
    finally:
        asyncio.run = run


def make_executor(nodes: Sequence[Node], kind: str | None = None,
                  context: Context | None = None) -> Executor:
    """The executor the nodes of a process spin on (`kind`, default `executor_kind()`).

    The events executor cannot serve guard conditions: a process with one spins on the
    single-threaded executor whatever was asked (and says so where $ZEUS_EXECUTOR asked for
    events); the container's intra-process bus holds none (it runs as executor tasks). The
    nodes are added to the executor returned (on `context`, default rclpy's).
    """
    kind = kind or executor_kind()
    guarded = [node.get_name() for node in nodes if list(node.guards)]
    if kind == 'events' and guarded:
        # Said where someone asked for events; the default just takes what works.
        asked = os.environ.get(EXECUTOR_ENV, '').strip().lower() == 'events'
        log = nodes[0].get_logger().info if asked else nodes[0].get_logger().debug
        log(f'node(s) {", ".join(guarded)} hold a guard condition, '
            'which the events executor cannot serve: spinning on the single-threaded executor')
        kind = 'single'
    executor = _events_executor(context) if kind == 'events' else \
        SingleThreadedExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    for node in nodes:  # deliver what a container's nodes published while being built
        bus = getattr(node, 'intra_process', None)
        if bus is not None:
            bus.wake()
    return executor


def _finished(nodes: Sequence[Node]) -> bool:
    """True once a node says it has done its job (its `finished` attribute)."""
    return any(getattr(node, 'finished', False) for node in nodes)


def _spin_until_signal(executor: Executor, signals: list[int], nodes: Sequence[Node] = ()
                       ) -> None:
    """Spin until a stop signal (noted in `signals` by our handler), a shutdown or a finish.

    A finish: one of `nodes` has done its job (`_finished`).
    """
    while not signals and rclpy.ok() and not _finished(nodes):
        executor.spin_once(timeout_sec=0.1)


def _drain(executor: Executor, nodes: Sequence[Node], quiet: float) -> None:
    """After a stop signal: spin on until no message came for `quiet` s (DRAIN_LIMIT_S).

    `zeus launch` stops a recorder after the nodes it records: what they published last may
    still wait in this process's DDS queues (a recorder behind a fast loop, ~20 steps), and the
    bag must hold it. Messages are counted by the nodes' `received` attribute.
    """
    def received() -> int:
        return sum(int(getattr(node, 'received', 0)) for node in nodes)

    limit = time.monotonic() + DRAIN_LIMIT_S
    seen, quiet_since = received(), time.monotonic()
    while rclpy.ok() and time.monotonic() < min(limit, quiet_since + quiet):
        executor.spin_once(timeout_sec=0.05)
        if received() != seen:
            seen, quiet_since = received(), time.monotonic()


def params_file_errors(args: Sequence[str]) -> list[str]:
    """What is wrong with each `--params-file` in a node's arguments, one line each.

    rcl reads these files inside rclpy.init and fails with a long RCLError traceback; read here
    first, a missing file, bad YAML or a file not shaped `<node>: ros__parameters: {...}` is
    one line naming the file and the fix.
    """
    import yaml

    errors = []
    paths = [args[i + 1] for i, arg in enumerate(args[:-1]) if arg == '--params-file']
    for path in paths:
        where = f'--params-file {path}'
        try:
            data = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
        except OSError as error:
            errors.append(f'{where}: cannot read it ({error.strerror})')
            continue
        except (yaml.YAMLError, UnicodeDecodeError) as error:
            mark = getattr(error, 'problem_mark', None)
            line = f' line {mark.line + 1}' if mark is not None else ''
            errors.append(f'{where}{line}: not valid YAML '
                          f'({getattr(error, "problem", None) or error})')
            continue
        if not isinstance(data, dict) or not data:
            errors.append(f'{where}: expected a mapping of node names, e.g. '
                          '"/**/policy: {ros__parameters: {checkpoint: ...}}"')
            continue
        for name, section in data.items():
            if not isinstance(section, dict) or not isinstance(
                    section.get('ros__parameters'), dict):
                errors.append(f'{where}: node {name!r} needs a ros__parameters: mapping '
                              '(the ROS 2 params file layout)')
                break
    return errors


def _stop_signal(signals: list[int], signum: int) -> None:
    """Note a stop signal for the spin loop; the first one bounds the whole stop."""
    if not signals:
        start_stop_limit()
    signals.append(signum)


def run_nodes(factories: Sequence[Callable[[], Node]], args: list[str] | None = None,
              drain: float = 0.0) -> NoReturn:
    """`run_node` for several nodes in one process on one executor (a component container).

    The nodes are built in order (a ValueError from any stops them all: exit code 2), spin
    together on `make_executor`'s executor until a signal, an external shutdown or one of them
    finishes (NodeFinished, or its `finished` attribute set), are destroyed and closed in
    order, and the exit code is the first non-zero `exit_code`.
    """
    bad = params_file_errors(sys.argv[1:] if args is None else args)
    if bad:
        print(f'error: {bad[0]}', file=sys.stderr)
        _exit_now(2)
    signals: list[int] = []
    for stop_signal in (signal.SIGINT, signal.SIGTERM):
        signal.signal(stop_signal, lambda signum, _frame: _stop_signal(signals, signum))
    # `kill -USR1 <pid>`: every thread's Python stack on stderr, the node running on; for a
    # node that does not stop or answer (a test times out on it and asks it).
    faulthandler.register(STACKS_SIGNAL, all_threads=True)
    # The signals are ours: rclpy's handlers would shut the context down at once, and what a
    # node published last would be lost with its publishers (a recorder one step short).
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    nodes: list[Node] = []
    try:
        kind = executor_kind()  # a bad $ZEUS_EXECUTOR stops the process as a bad parameter
        for factory in factories:
            nodes.append(factory())
    except ValueError as error:
        print(f'error: {error}', file=sys.stderr)
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
        _exit_now(2)
    executor = make_executor(nodes, kind)
    try:
        _spin_until_signal(executor, signals, nodes)
        if _finished(nodes):
            raise NodeFinished
        if drain:
            _drain(executor, nodes, drain)
        else:
            _deliver_published(nodes, timeout=STOP_DELIVERY_S)
    except NodeFinished:
        _deliver_published(nodes)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # A signal that shuts the context down while a callback publishes surfaces as an
        # RCLError from that callback: that is a normal stop, not a crash.
        if rclpy.ok():
            raise
    finally:
        with bounded():  # never hang here (shutdown.py): past the limit, stacks and exit 1
            for node in nodes:  # as rclpy.spin leaves its executor
                executor.remove_node(node)
            if not isinstance(executor, SingleThreadedExecutor):
                executor.shutdown()  # the events executor drops its rcl callbacks only here
            # Destroyed first, then closed (close() may log its summary after its node is gone).
            for node in nodes:
                node.destroy_node()
        for node in nodes:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
        with bounded():
            rclpy.try_shutdown()  # also finalizes ROS logging (log files flushed)
    codes = [int(getattr(node, 'exit_code', 0)) for node in nodes]
    _exit_now(next((code for code in codes if code), 0))
