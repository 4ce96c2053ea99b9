"""`zeus inspect`: watch the context topics live; it only subscribes, never changes anything.

The terminal view refreshes once a second (not on a terminal, as in a log file or a pipe: one
line every 10 s, PIPE_REFRESH_S): the true context against the estimate in the
context's own units (the read-out the estimator publishes on zeus/context_readout when its
checkpoint holds one; psi otherwise), the current segment's return, the step rate,
observation-to-action latency and the health counters that the nodes publish on /diagnostics.
`--png` saves the inspection figure and `--csv` the per-step log when the inspector stops
(Ctrl-C, `--duration` or `--steps`). With nothing publishing it waits quietly after one hint
(domain, namespace) and exits 1 when it stops without having seen a step (130 when Ctrl-C
stopped it: one line, never a traceback, however often Ctrl-C is pressed).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator, Sequence
import contextlib
from dataclasses import dataclass
import os
from pathlib import Path
import signal
import sys
import time
from typing import IO, Any

import numpy as np

from zeus_ros.cli_args import ZeusArgumentParser, at_least
from zeus_ros.step_log import (
    SeenStep,
    StepLog,
    format_segments,
    percentile,
    plot_inspection,
)

DIAGNOSTICS_STALE_S = 5.0
"""Seconds without a node's status before the view calls it STALE (diagnostic_aggregator's
GenericAnalyzer `timeout` default; the nodes publish every 1 s, the trainer every 5 s)."""
LEVELS = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}
DISCOVERY_SETTLE_S = 2.0
"""Seconds after the first step before a step without an estimate means 'no estimator'."""
TERMINAL_REFRESH_S = 1.0
"""Seconds between views on a terminal (the --refresh default there)."""
PIPE_REFRESH_S = 10.0
"""Seconds between lines when stdout is no terminal: a log must not grow a block a second."""
NOTHING_HINT = ('is a system running (zeus launch, zeus demo)? It must use the same '
                'ROS_DOMAIN_ID (and --namespace, if it runs in one)')


def received_s(info: Any) -> float:
    """When the middleware received a message (s): not when the executor got round to it.

    The executor serves ready subscriptions in its own order, so a step and its action taken
    in one spin would read as a negative observation -> action latency on the handling time.
    """
    return info['received_timestamp'] * 1e-9


class Inspector:
    """ROS subscriber that fills a StepLog (imports rclpy only when constructed)."""

    def __init__(self, namespace: str = '', name: str = 'zeus_inspect',
                 expect: Sequence[str] = (), expect_timeout: float = 20.0) -> None:
        """`expect`: topics (TOPICS values) whose publishers must be matched before the steps.

        An inspector that a launch waits for by name (the demo's: sim_bridge `observers`)
        subscribes to the steps only once its readers hear the expected publishers, as the
        recorder does: else a fast loop can run to its end before this reader matches the
        estimator, and the view (and the demo's frozen run) has no context at all.
        """
        from diagnostic_msgs.msg import DiagnosticArray
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions
        from zeus_msgs.msg import Action, ContextEstimate, ContextTruth, StepFeedback

        from zeus_ros.nodes.topics import STEP_BACKLOG, TOPICS, step_qos

        readable = (TOPICS.STEP, TOPICS.CONTEXT_TRUTH, TOPICS.CONTEXT, TOPICS.CONTEXT_READOUT,
                    TOPICS.CONTEXT_NOVELTY, TOPICS.ACTION)
        unknown = sorted(set(expect) - set(readable))
        if unknown:  # before rclpy.init: nothing to clean up
            raise ValueError(f'Inspector: expect names {unknown}; it reads {list(readable)}')
        # The signals are the owner's (a KeyboardInterrupt, or `zeus inspect`'s stop flag):
        # rclpy's own handler would shut the context down under the running view, and every
        # call after that (spin, count_publishers, close) raises.
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        self.stop_signal: int | None = None
        self.namespace = namespace
        self.started = time.monotonic()
        self.first_step_at: float | None = None
        self.task = ''
        """The task the steps name (StepFeedback.task): the read-out's units come from it."""
        # In the system's namespace, the relative zeus topics resolve to that system's.
        self.node = rclpy.create_node(name, namespace=namespace)
        # One executor for the whole run: rclpy.spin_once() would build a new one per call.
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.log = StepLog()
        self.health: dict[str, dict[str, str]] = {}
        self.statuses: dict[str, HeardStatus] = {}
        """Every /diagnostics status by name: level, message, when it last arrived."""
        # As deep as the publishers' history (and the recorder's): an inspector starved of CPU
        # for a second (a busy machine) must not lose steps, or the demo's per-segment
        # returns of the live and the frozen run stop being comparable.
        qos = step_qos(depth=STEP_BACKLOG)
        node = self.node
        readers = {
            TOPICS.CONTEXT_TRUTH: node.create_subscription(ContextTruth, TOPICS.CONTEXT_TRUTH,
                                                           self._on_truth, qos),
            TOPICS.CONTEXT: node.create_subscription(ContextEstimate, TOPICS.CONTEXT,
                                                     self._on_context, qos),
            TOPICS.CONTEXT_READOUT: node.create_subscription(
                ContextTruth, TOPICS.CONTEXT_READOUT, self._on_readout, qos),
            TOPICS.CONTEXT_NOVELTY: node.create_subscription(
                ContextTruth, TOPICS.CONTEXT_NOVELTY, self._on_novelty, qos),
            TOPICS.ACTION: node.create_subscription(Action, TOPICS.ACTION, self._on_action, qos),
        }
        self._topics = {'context': readers[TOPICS.CONTEXT].topic_name,
                        'readout': readers[TOPICS.CONTEXT_READOUT].topic_name}
        node.create_subscription(DiagnosticArray, TOPICS.DIAGNOSTICS, self._on_diag, 10)

        def subscribe_steps() -> None:
            node.create_subscription(StepFeedback, TOPICS.STEP, self._on_step, qos)

        if expect:
            self._take_steps_when_heard(readers, expect, expect_timeout, subscribe_steps)
        else:  # a bystander: from whatever step it first hears
            subscribe_steps()

    def _take_steps_when_heard(self, readers: dict[str, Any], expect: Sequence[str],
                               timeout: float, subscribe_steps: Callable[[], None]) -> None:
        """Subscribe to the steps once the `expect`ed publishers are matched (or on timeout)."""
        from zeus_ros.nodes.peers import call_when_ready, unmatched_readers
        from zeus_ros.nodes.topics import TOPICS

        node = self.node

        def unheard() -> list[str]:
            return unmatched_readers(node, [(reader, 1) for topic, reader in readers.items()
                                            if topic in expect],
                                     sources=[TOPICS.STEP] if TOPICS.STEP in expect else [])

        call_when_ready(node, unheard, subscribe_steps, timeout, 'expect_timeout',
                        'subscribing to the steps anyway: the view may miss the first contexts')

    def _on_step(self, msg: object, info: Any) -> None:
        if self.first_step_at is None:
            self.first_step_at = time.monotonic()
        if not self.task and msg.task:
            self.task = msg.task
        record = self.log.record(msg.step)
        record.episode, record.first, record.reward = msg.episode, msg.first, msg.reward
        record.t_observation = received_s(info)

    def _on_truth(self, msg: object) -> None:
        record = self.log.record(msg.step)
        record.truth = tuple(float(v) for v in msg.values)
        record.segment = msg.segment
        if not self.log.context_names:
            self.log.context_names = tuple(msg.names)

    def _on_context(self, msg: object) -> None:
        record = self.log.record(msg.step)
        record.estimate = np.asarray(msg.data, dtype=np.float32)
        record.history_length = msg.history_length

    def _on_readout(self, msg: object) -> None:
        self.log.record(msg.step).readout = tuple(float(v) for v in msg.values)

    def _on_novelty(self, msg: object) -> None:
        values = dict(zip(msg.names, msg.values, strict=False))
        self.log.record(msg.step).novelty = (values['novelty'], values['threshold'])

    def _on_action(self, msg: object, info: Any) -> None:
        self.log.record(msg.step).t_action = received_s(info)

    def _on_diag(self, msg: object) -> None:
        now = time.monotonic()
        for status in msg.status:
            self.health[status.name] = {kv.key: kv.value for kv in status.values}
            heard = self.statuses.get(status.name)
            self.statuses[status.name] = HeardStatus(
                int.from_bytes(status.level, 'little') if isinstance(status.level, bytes)
                else int(status.level), status.message, status.hardware_id, now,
                now - heard.at if heard else 0.0)

    def spin(self, duration: float | None, steps: int | None, refresh: float | None,
             quiet: bool, out: IO[str] | None = None) -> None:
        """Spin until the limit, a stop signal or Ctrl-C, showing a view every `refresh` s.

        `refresh` None: every 1 s on a terminal, every 10 s otherwise (`refresh_s`).
        """
        import rclpy

        out = sys.stdout if out is None else out
        refresh = refresh_s(out, refresh)
        start = time.monotonic()
        next_draw = start + refresh
        hinted = False
        try:
            while rclpy.ok() and self.stop_signal is None:
                self.executor.spin_once(timeout_sec=0.05)
                now = time.monotonic()
                if duration is not None and now - start > duration:
                    break
                if steps is not None and len(self.log.records) >= steps:
                    break
                if quiet or now < next_draw:
                    continue
                next_draw = now + refresh
                if self.current() is not None:
                    self.show(out)
                elif not hinted and self.first_step_at is None:  # one hint, then quiet
                    print(self.waiting_hint(), file=out, flush=True)
                    hinted = True
        except KeyboardInterrupt:
            pass

    def show(self, out: IO[str]) -> None:
        """The view on a terminal; one line of it (`one_line`) in a log file or a pipe."""
        view = self.view()
        print(view if _is_terminal(out) else one_line(view), file=out, flush=True)

    def listening(self) -> str:
        """Which topics in which domain: '/zeus/* in ROS_DOMAIN_ID=42 (discovery LOCALHOST)'."""
        where = f'{self.namespace.rstrip("/")}/zeus/*' if self.namespace.strip('/') \
            else '/zeus/*'
        return (f'{where} in ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")} (discovery '
                f'{os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")})')

    def waiting_hint(self) -> str:
        """Where the inspector listens, and what to check when nothing arrives."""
        return f'[inspect] waiting for {self.listening()}; {NOTHING_HINT}'


    def current(self, settled: bool = True) -> SeenStep | None:
        """The newest step seen whole, or None before the first one.

        `settled`: none while the graph may still be undiscovered (`discovering`).

        Whole: feedback and true context, and the estimate (and its read-out) when an estimator
        publishes them. Parts of later steps still in flight are not shown, so no half-filled
        line appears.
        """
        records = self.log.ordered()
        # An estimator that is up but whose first estimate is still in flight counts as one.
        estimating = any(r.estimate is not None for r in records[-50:]) or \
            self.node.count_publishers(self._topics['context']) > 0
        if settled and not estimating and self.discovering():
            return None  # the estimator may exist and be not yet discovered: no verdict
        reading = any(r.readout is not None for r in records[-50:]) or \
            self.node.count_publishers(self._topics['readout']) > 0
        for record in reversed(records):
            if record.episode >= 0 and record.truth is not None \
                    and (record.estimate is not None or not estimating) \
                    and (record.readout is not None or not reading):
                return record
        return None

    def discovering(self) -> bool:
        """Whether the steps began so recently that the rest of the graph may be unknown yet.

        DDS discovers each node on its own: an inspector started beside a launch can hear the
        step source a moment before it discovers the estimator, and would call that step
        'no estimator'. Within DISCOVERY_SETTLE_S of the first step it gives no verdict.
        """
        return self.first_step_at is not None and \
            time.monotonic() - self.first_step_at < DISCOVERY_SETTLE_S

    def step_rate(self, window: int = 200) -> float | None:
        """Steps per second over the newest `window` steps (None before two steps)."""
        times = [r.t_observation for r in self.log.ordered()[-window:]
                 if r.t_observation is not None]
        if len(times) < 2 or times[-1] <= times[0]:
            return None
        return (len(times) - 1) / (times[-1] - times[0])

    def unit(self, parameter: str) -> str:
        """' [unit]' of a context parameter from the task's family file ('' when unknown)."""
        from sim_bridge.families import family

        try:
            unit = family(self.task).unit(parameter) if self.task else ''
        except ValueError:  # a robot or a task file this process does not know
            unit = ''
        return f' [{unit}]' if unit else ''

    def estimate_text(self, record: SeenStep) -> str:
        """'torso_length: estimated 1.21, true 1.25' with a read-out, else psi's first values."""
        names = self.log.context_names
        truth = record.truth or ()
        if record.readout:
            return '; '.join(f'{n}: estimated {e:.3g}, true {t:.3g}{self.unit(n)}' for n, e, t in
                             zip(names, record.readout, truth, strict=False))
        true = ', '.join(f'{n}={v:.3g}' for n, v in zip(names, truth, strict=False))
        if record.estimate is None:
            return f'true {true} | no estimator'
        psi = np.array2string(record.estimate[:4], precision=2, suppress_small=True)
        return f'true {true} | psi[:4] {psi} (no read-out in the checkpoint)'

    def view(self) -> str:
        """The terminal view of the newest whole step."""
        last = self.current()
        if last is None:
            return self.waiting_hint()
        segments = self.log.segments()
        current = segments[-1] if segments else None
        latency = self.log.latencies_ms()[-200:]
        rate = self.step_rate()
        novelty = ''
        if last.novelty:
            score, threshold = last.novelty
            novelty = (f' | novelty {score:.2f} > {threshold:.2f}: NOT A TRAINING CONTEXT'
                       if score > threshold else f' | novelty {score:.2f} (< {threshold:.2f})')
        lines = [
            f'[inspect] step {last.step} episode {last.episode} segment {last.segment} '
            f'(H={last.history_length}): {self.estimate_text(last)}{novelty}',
            f'          segment return {current.total_return if current else 0:.2f} over '
            f'{current.steps if current else 0} steps | '
            + (f'{rate:.0f} steps/s | ' if rate is not None else '')
            + f'latency p50 {percentile(latency, 50):.1f} ms p99 '
            f'{percentile(latency, 99):.1f} ms',
        ]
        now = time.monotonic()
        for name, values in sorted(self.health.items()):
            heard = self.statuses.get(name)
            state = heard.state(now) if heard else ''  # STALE: the counters below are old news
            # A node's rate is 0.0 until its window holds two events: not shown until then.
            shown = ', '.join(f'{k}={v}' for k, v in values.items()
                              if k in ('rate_hz', 'timeouts', 'rejected', 'stale', 'safe',
                                       'gaps', 'drops', 'dropped', 'novel_steps', 'state',
                                       'round_phase', 'round_progress', 'round_gain',
                                       'round_phase_eta_s', 'swaps', 'refusals',
                                       'rollbacks')
                              and not (k == 'rate_hz' and _is_zero(v)))
            if shown or state:
                parts = (state, shown) if state.startswith('STALE') else (shown, state)
                lines.append(f'          {name}: ' + ' | '.join(filter(None, parts)))
        return '\n'.join(lines)

    def close(self) -> None:
        """Destroy the node and shut rclpy down."""
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown()


@contextlib.contextmanager
def stop_on_signals(inspector: Inspector) -> Iterator[None]:
    """SIGINT / SIGTERM only set `inspector.stop_signal` inside: the loop ends between spins.

    No exception can then land inside rclpy (the spin, the node's destruction), and more
    Ctrl-C while the inspector shuts down, reports and exits change nothing: it is stopping
    already (ignored, not merely noted: Python gives SIGINT its default action back while the
    interpreter exits). Stopped by a limit instead (--duration, --steps), the previous handlers
    come back, so a Ctrl-C during the summary and figure is an ordinary KeyboardInterrupt.
    """
    def note(signum: int, _frame: object) -> None:
        inspector.stop_signal = signum

    previous = {sig: signal.signal(sig, note) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if inspector.stop_signal is None else signal.SIG_IGN)


@dataclass
class HeardStatus:
    """One /diagnostics status as the inspector last heard it."""

    level: int
    message: str
    hardware_id: str
    at: float  # monotonic time it arrived
    interval: float  # seconds since the one before (0: the first)

    def silent_after(self) -> float:
        """Seconds without it before it is STALE: DIAGNOSTICS_STALE_S, or 3 of its periods."""
        return max(DIAGNOSTICS_STALE_S, 3 * self.interval)

    def state(self, now: float) -> str:
        """'' while it arrives and is OK; else one line: STALE, or its level and summary."""
        from zeus_ros.nodes.diagnostics import summary

        silent = now - self.at
        if silent > self.silent_after():
            return (f'STALE: no /diagnostics for {silent:.0f} s (was {LEVELS.get(self.level, "?")}'
                    f' [{self.hardware_id}])')
        if self.level == 0:
            return ''
        return f'{LEVELS.get(self.level, str(self.level))}: {summary(self.message)}'


def _is_terminal(out: IO[str]) -> bool:
    isatty = getattr(out, 'isatty', None)
    return bool(isatty and isatty())


def refresh_s(out: IO[str], given: float | None) -> float:
    """Seconds between views: `given` (--refresh), else 1 s on a terminal, 10 s otherwise."""
    if given is not None:
        return given
    return TERMINAL_REFRESH_S if _is_terminal(out) else PIPE_REFRESH_S


def one_line(view: str) -> str:
    """The view's lines joined by ' | ': one line per update for a log file (issue 52)."""
    return ' | '.join(line.strip() for line in view.splitlines() if line.strip())


def _is_zero(text: str) -> bool:
    try:
        return float(text) == 0.0
    except ValueError:
        return False


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus inspect`; 1 when it saw no step."""
    parser = ZeusArgumentParser(prog='zeus inspect', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--duration', type=at_least(0.0, float), default=None,
                        help='stop after N seconds')
    parser.add_argument('--steps', type=at_least(1), default=None, help='stop after N steps')
    parser.add_argument('--png', type=Path, default=None, help='save the figure here at the end')
    parser.add_argument('--csv', type=Path, default=None, help='save the per-step log here')
    parser.add_argument('--refresh', type=at_least(0.05, float), default=None,
                        help=f'seconds between views (default {TERMINAL_REFRESH_S:g} on a '
                        f'terminal; otherwise {PIPE_REFRESH_S:g}, one line each)')
    parser.add_argument('--quiet', action='store_true', help='no live view, only the summary')
    parser.add_argument('--namespace', default='',
                        help='watch the system in this namespace (e.g. r1 for /r1/zeus/...)')
    args = parser.parse_args(argv)
    try:
        return _inspect(args)
    except KeyboardInterrupt:  # a Ctrl-C after the view stopped (summary, CSV, figure)
        print('zeus inspect: interrupted', file=sys.stderr)
        return 130


def _inspect(args: argparse.Namespace) -> int:
    """Watch until a limit or a stop signal, then print the summary and write the files."""
    inspector = Inspector(namespace='/' + args.namespace.strip('/'))
    with stop_on_signals(inspector):
        try:
            inspector.spin(args.duration, args.steps, args.refresh, args.quiet)
            seen = inspector.current(settled=False) is not None
        finally:
            inspector.close()
    log = inspector.log
    if not seen:
        interrupted = inspector.stop_signal == signal.SIGINT
        print(f'zeus inspect: {"interrupted; " if interrupted else ""}saw no step on '
              f'{inspector.listening()} in {time.monotonic() - inspector.started:.0f} s; '
              f'{NOTHING_HINT}', file=sys.stderr)
        return 130 if interrupted else 1
    print(format_segments(log.segments(), log.context_names))
    if args.csv:
        print(f'[inspect] per-step log: {log.save_csv(args.csv)}')
    if args.png:
        print(f'[inspect] figure: {plot_inspection(log, args.png, "zeus inspect")}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
