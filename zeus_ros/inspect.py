"""`zeus inspect`: watch the context topics live; it only subscribes, never changes anything.

The terminal view refreshes once a second: the true context against the learned estimate, the
current segment's return, observation-to-action latency and the health counters that the nodes
publish on /diagnostics. `--png` saves the inspection figure and `--csv` the per-step log when
the inspector stops (Ctrl-C, `--duration` or `--steps`).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path
import sys
import time

import numpy as np

from zeus_ros.cli_args import ZeusArgumentParser
from zeus_ros.inspection import StepLog, format_segments, percentile, plot_inspection


def write_csv(log: StepLog, path: Path) -> Path:
    """One row per step: truth, estimate, reward, latency."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(['step', 'episode', 'segment', 'first', 'reward',
                         *[f'true_{n}' for n in log.context_names], 'history_length',
                         'latency_ms', 'psi'])
        for r in log.ordered():
            psi = '' if r.estimate is None else ' '.join(f'{v:.5g}' for v in r.estimate)
            latency = '' if r.latency_ms is None else f'{r.latency_ms:.3f}'
            writer.writerow([r.step, r.episode, r.segment, int(r.first), f'{r.reward:.6g}',
                             *(r.truth or ()), r.history_length, latency, psi])
    return path


class Inspector:
    """ROS subscriber that fills a StepLog (imports rclpy only when constructed)."""

    def __init__(self, namespace: str = '') -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from zeus_msgs.msg import Action, ContextEstimate, ContextTruth, StepFeedback

        from zeus_ros.nodes.common import TOPICS, step_qos

        rclpy.init()
        # In the system's namespace, the relative zeus topics resolve to that system's.
        self.node = rclpy.create_node('zeus_inspect', namespace=namespace)
        # One executor for the whole run: rclpy.spin_once() would build a new one per call.
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.log = StepLog()
        self.health: dict[str, dict[str, str]] = {}
        qos = step_qos(depth=50)
        node = self.node
        node.create_subscription(StepFeedback, TOPICS.STEP, self._on_step, qos)
        node.create_subscription(ContextTruth, TOPICS.CONTEXT_TRUTH, self._on_truth, qos)
        node.create_subscription(ContextEstimate, TOPICS.CONTEXT, self._on_context, qos)
        node.create_subscription(Action, TOPICS.ACTION, self._on_action, qos)
        node.create_subscription(DiagnosticArray, TOPICS.DIAGNOSTICS, self._on_diag, 10)

    def _on_step(self, msg: object) -> None:
        record = self.log.record(msg.step)
        record.episode, record.first, record.reward = msg.episode, msg.first, msg.reward
        record.t_observation = time.monotonic()

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

    def _on_action(self, msg: object) -> None:
        self.log.record(msg.step).t_action = time.monotonic()

    def _on_diag(self, msg: object) -> None:
        for status in msg.status:
            self.health[status.name] = {kv.key: kv.value for kv in status.values}

    def spin(self, duration: float | None, steps: int | None, refresh: float,
             quiet: bool) -> None:
        """Spin until the limit or Ctrl-C, redrawing the view every `refresh` seconds."""
        import rclpy

        start = time.monotonic()
        next_draw = start + refresh
        try:
            while rclpy.ok():
                self.executor.spin_once(timeout_sec=0.05)
                now = time.monotonic()
                if duration is not None and now - start > duration:
                    break
                if steps is not None and len(self.log.records) >= steps:
                    break
                if not quiet and now >= next_draw:
                    print(self.view(), flush=True)
                    next_draw = now + refresh
        except KeyboardInterrupt:
            pass

    def view(self) -> str:
        """The terminal view of the newest state."""
        records = self.log.ordered()
        if not records:
            return '[inspect] waiting for /zeus topics ...'
        last = records[-1]
        segments = self.log.segments()
        current = segments[-1] if segments else None
        latency = self.log.latencies_ms()[-200:]
        names = self.log.context_names
        truth = ', '.join(f'{n}={v:.3g}' for n, v in zip(names, last.truth or (), strict=False))
        psi = '-' if last.estimate is None else np.array2string(
            last.estimate[:4], precision=2, suppress_small=True)
        lines = [
            f'[inspect] step {last.step} episode {last.episode} segment {last.segment}: '
            f'true {truth or "?"} | psi[:4] {psi} (H={last.history_length})',
            f'          segment return {current.total_return if current else 0:.2f} over '
            f'{current.steps if current else 0} steps | latency p50 '
            f'{percentile(latency, 50):.1f} ms p99 {percentile(latency, 99):.1f} ms',
        ]
        for name, values in sorted(self.health.items()):
            shown = ', '.join(f'{k}={v}' for k, v in values.items()
                              if k in ('rate_hz', 'timeouts', 'rejected', 'stale', 'safe',
                                       'gaps', 'drops', 'dropped'))
            lines.append(f'          {name}: {shown}')
        return '\n'.join(lines)

    def close(self) -> None:
        """Destroy the node and shut rclpy down."""
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown()


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus inspect`."""
    parser = ZeusArgumentParser(prog='zeus inspect', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--duration', type=float, default=None, help='stop after N seconds')
    parser.add_argument('--steps', type=int, default=None, help='stop after N steps')
    parser.add_argument('--png', type=Path, default=None, help='save the figure here at the end')
    parser.add_argument('--csv', type=Path, default=None, help='save the per-step log here')
    parser.add_argument('--refresh', type=float, default=1.0, help='seconds between redraws')
    parser.add_argument('--quiet', action='store_true', help='no live view, only the summary')
    parser.add_argument('--namespace', default='',
                        help='watch the system in this namespace (e.g. r1 for /r1/zeus/...)')
    args = parser.parse_args(argv)
    inspector = Inspector(namespace='/' + args.namespace.strip('/'))
    try:
        inspector.spin(args.duration, args.steps, args.refresh, args.quiet)
    finally:
        inspector.close()
    log = inspector.log
    print(format_segments(log.segments(), log.context_names))
    if args.csv:
        print(f'[inspect] per-step log: {write_csv(log, args.csv)}')
    if args.png:
        print(f'[inspect] figure: {plot_inspection(log, args.png, "zeus inspect")}')
    return 0 if log.records else 1


if __name__ == '__main__':
    sys.exit(main())
