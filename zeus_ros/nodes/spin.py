"""How a node process runs: its executor, its stop signals, draining and a bounded exit.

Every zeus_ros node process (and the one-process container) is `run_node` / `run_nodes`: one
clear line and exit code 2 for bad parameters, the executor `$ZEUS_EXECUTOR` names, Ctrl-C and
SIGTERM ending the spin so that what a node published last still reaches its readers, and an
exit that never hangs (shutdown.py).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import faulthandler
import os
from pathlib import Path
import signal
import sys
import time
from typing import TYPE_CHECKING, Any, NoReturn

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from zeus_ros.nodes.sender_subscription import raise_callback_error
from zeus_ros.nodes.shutdown import bounded, start_stop_limit

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.node import Node

__all__ = [
    'DRAIN_LIMIT_S',
    'EXECUTORS',
    'EXECUTOR_ENV',
    'STACKS_SIGNAL',
    'STOP_DELIVERY_S',
    'NodeFinished',
    'executor_kind',
    'make_executor',
    'params_file_errors',
    'run_node',
    'run_nodes',
]


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


def _deliver_published(nodes: Sequence[Node], timeout: float = 5.0) -> None:
    """A node finished its job: let reliable readers (a recorder) take what it last published.

    Destroying a publisher drops what its readers have not acknowledged yet; a recorder that
    runs a little behind would lose the last steps of a run. Waits `timeout` seconds at most
    (no wait when they are caught up; 2 s once lost the last steps of a one-process loop to a
    recorder starved by a three-worker test run on two cores).
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
        for node in nodes:  # a paired subscription's callback failed: its traceback, exit 1
            raise_callback_error(node)


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
    one line naming the file and the fix. Read as rcl reads it (ParamsLoader): the files
    launch_ros writes tag every list `!!python/tuple`, and rcl accepts them.
    """
    import yaml

    from zeus_ros.yaml_text import safe_load_params

    errors = []
    paths = [args[i + 1] for i, arg in enumerate(args[:-1]) if arg == '--params-file']
    for path in paths:
        where = f'--params-file {path}'
        try:
            data = safe_load_params(Path(path).read_text(encoding='utf-8'))
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
