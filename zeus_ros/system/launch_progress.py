"""`zeus launch`'s status line: steps, rate, episode and the current context segment's return.

A subscriber in the launcher process listens to zeus/step and zeus/context_truth (it never
publishes). sim_bridge waits for the group's nodes by name (`observers`,
launch_defaults.start_parameters), so this subscriber cannot stand in for a node not yet
subscribed, which would then miss the first steps. On a terminal the status is one line
rewritten in place under the nodes' output; into a file or pipe it is a plain line every
`every` seconds.
"""

from __future__ import annotations

from collections import deque
import os
import sys
import threading
import time
from typing import IO, Any

__all__ = ['Progress', 'ProgressState']


class ProgressState:
    """What the status line shows, updated from the step messages (no ROS here)."""

    def __init__(self) -> None:
        self.steps = 0
        self.last_step = -1
        self.episode = -1
        self.segment = -1
        self.segment_return = 0.0
        self.context = ''
        self._times: deque[float] = deque(maxlen=200)

    def on_step(self, step: int, episode: int, reward: float, first: bool,
                now: float | None = None) -> None:
        """One StepFeedback: count it and add its reward to the current segment."""
        self.steps += 1
        self.last_step, self.episode = step, episode
        if not first:
            self.segment_return += reward
        self._times.append(time.monotonic() if now is None else now)

    def on_truth(self, segment: int, names: Any, values: Any) -> None:
        """One ContextTruth: a new segment restarts the segment's return."""
        if segment != self.segment:
            self.segment, self.segment_return = segment, 0.0
        self.context = ', '.join(f'{n}={v:.3g}' for n, v in zip(names, values, strict=False))

    @property
    def rate(self) -> float | None:
        """Steps per second over the newest steps (None before two)."""
        if len(self._times) < 2 or self._times[-1] <= self._times[0]:
            return None
        return (len(self._times) - 1) / (self._times[-1] - self._times[0])

    def line(self) -> str:
        """The status text."""
        if self.steps == 0:
            return '[zeus launch] waiting for the first step ...'
        rate = self.rate
        return (f'[zeus launch] step {self.last_step} ({self.steps} seen) | '
                + (f'{rate:.0f} steps/s | ' if rate is not None else '')
                + f'episode {self.episode} | segment {self.segment}'
                + (f' ({self.context})' if self.context else '')
                + f' return {self.segment_return:.2f}')


class _StatusOut:
    """A text stream for the nodes' lines that keeps the status line below them."""

    def __init__(self, out: IO[str], state: ProgressState, tty: bool) -> None:
        self.out, self.state, self.tty = out, state, tty
        self.lock = threading.RLock()
        self.shown = False

    def write(self, text: str) -> int:
        with self.lock:
            if self.shown:
                self.out.write('\r\033[K')
                self.shown = False
            return self.out.write(text)

    def flush(self) -> None:
        with self.lock:
            if self.tty and not self.shown:
                self.out.write(self.state.line())
                self.shown = True
            self.out.flush()

    def draw(self) -> None:
        """Rewrite the status line (terminal) or print it as a line (file, pipe)."""
        with self.lock:
            if self.tty:
                self.out.write('\r\033[K' + self.state.line())
                self.shown = True
            else:
                self.out.write(self.state.line() + '\n')
            self.out.flush()

    def finish(self) -> None:
        """Leave the last status on its own line."""
        with self.lock:
            if self.tty and self.shown:
                self.out.write('\n')
                self.shown = False
            self.out.flush()


class Progress:
    """The subscriber and the redraw loop, on a background thread."""

    def __init__(self, env: dict[str, str], namespace: str, out: IO[str] = sys.stdout,
                 every: float | None = None) -> None:
        """Subscribe in the launch's domain and namespace; `every`: seconds between draws."""
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from zeus_msgs.msg import ContextTruth, StepFeedback

        from zeus_ros.nodes.topics import TOPICS, step_qos

        for key in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE'):
            os.environ[key] = env[key]
        tty = bool(getattr(out, 'isatty', lambda: False)())
        self.state = ProgressState()
        self.out = _StatusOut(out, self.state, tty)
        self.every = every if every is not None else (1.0 if tty else 10.0)
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('zeus_launch_progress', namespace=namespace or '/',
                                      context=self.context)
        qos = step_qos(depth=50)
        state = self.state
        self.node.create_subscription(
            StepFeedback, TOPICS.STEP,
            lambda m: state.on_step(m.step, m.episode, m.reward, m.first), qos)
        self.node.create_subscription(
            ContextTruth, TOPICS.CONTEXT_TRUTH,
            lambda m: state.on_truth(m.segment, m.names, m.values), qos)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        next_draw = time.monotonic() + self.every
        while not self._stop.is_set():
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except Exception:  # the context is shutting down
                break
            if time.monotonic() >= next_draw:
                self.out.draw()
                next_draw = time.monotonic() + self.every

    def close(self) -> None:
        """Stop the thread, print the final status, leave ROS."""
        self._stop.set()
        self._thread.join(timeout=2)
        self.out.draw()
        self.out.finish()
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()
