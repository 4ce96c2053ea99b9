"""sim_bridge node: a contextual MuJoCo task on ROS 2 topics, lockstep or realtime.

For step k it publishes observation o_k (state, and an 84x84 frame when `pixels` is on), the
StepFeedback (reward r_k of a_{k-1}, the action really applied), the true context c_k and /clock,
all with the same stamp (simulation time) and step index; then it waits for Action k (lockstep)
or applies the newest action on a wall-clock timer (realtime). The physics loop itself is
`sim_bridge.env.ScheduledEnv`, shared with the in-process tools. Its /diagnostics says how
long the loop takes to answer: StepFeedback k published to Action k received, p50 / p99 over
the last second and over the run (`latency_*_ms`, `latency_*_ms_run`), measured with no reader
of its own on the loop's topics, and checks the loop against an expected rate and latency
thresholds (nodes/health.py: WARN / ERROR that clear with their cause).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from zeus_msgs.msg import Action, ContextTruth, StateVector, StepFeedback

from sim_bridge.actions import ActionStatus
from sim_bridge.env import EnvStep, ScheduledEnv
from sim_bridge.registry import TASK_NAMES, make_task
from sim_bridge.schedules import schedule_from_config
from zeus_ros.nodes.diagnostics import set_device
from zeus_ros.nodes.handshake import handshake_of
from zeus_ros.nodes.health import (
    ClockWatch,
    WindowCounts,
    latency_problems,
    latency_specs,
    rate_problems,
)
from zeus_ros.nodes.messages import diagnostics_message, image_from_array, stamp_from_seconds
from zeus_ros.nodes.meters import LatencyMeter, RateMeter
from zeus_ros.nodes.params import LOCK_SPECS, Spec, declare_specs, serve_live_changes
from zeus_ros.nodes.peers import WaitReport, missing_peers, steady_timer
from zeus_ros.nodes.senders import PAIRING_SETTLE_S, SenderPairing, SenderSubscription
from zeus_ros.nodes.services import serve_trigger
from zeus_ros.nodes.spin import run_node
from zeus_ros.nodes.topics import TOPICS, image_qos, publisher_qos, step_qos

MODES = ('lockstep', 'realtime')
ACTION_BACKLOG = 1000  # reader history of zeus/action: room for a flood between two takes
SCHEDULE_PREFIX = 'schedule.'
ACTION_TIMEOUT_FLOOR = 0.1
"""Seconds: the least action_timeout. A policy answers within its latency_error_ms (200 ms by
default, p99 40 ms); below 0.1 s nearly every step would run the safe action (issue 49: 0.001
made 1,166 of 1,217 steps safe)."""
STALE_PERIODS = 2
"""A nonzero stale_action_age must span at least this many control periods (realtime)."""

SPECS: dict[str, Spec] = {
    'task': Spec('Cheetah-Run-v0', 'contextual MuJoCo task: ' + ', '.join(TASK_NAMES) +
                 ', or a task file (.yaml, sim_bridge/mjcf_task.py)'),
    'mode': Spec('lockstep', 'lockstep: step k+1 after Action k; realtime: wall-clock timer',
                 choices=MODES),
    'seed': Spec(0, "seeds the task's initial states and sampled schedules", low=0),
    'pixels': Spec(False, 'also publish rgb8 frames on zeus/observation/image'),
    'image_size': Spec(84, 'frame height and width in pixels', low=1, high=1024),
    'action_timeout': Spec(2.0, 'lockstep: seconds to wait for Action k before the safe action',
                           live=True, low=ACTION_TIMEOUT_FLOOR, safety=True),
    'control_rate': Spec(0.0, "realtime: steps per second (0: the task's own rate)", low=0.0),
    'stale_action_age': Spec(0.0, 'realtime: an older action is replaced (0: 3 periods)',
                             live=True, low=0.0, safety=True,
                             allowed=f'0, or at least {STALE_PERIODS} control periods'),
    'max_steps': Spec(0, 'stop after this many steps (0: run until stopped)', live=True, low=0,
                      safety=True),
    'wait_for_peers': Spec(True, 'start once a policy publishes actions and someone observes'),
    'peer_grace': Spec(0.5, 'seconds between seeing the peers and publishing step 0',
                       live=True, low=0.0),
    'min_observers': Spec(0, 'wait for this many zeus/step subscribers before step 0',
                          live=True, low=0),
    'observers': Spec([''], 'names of the nodes that must subscribe to zeus/step before step 0 '
                      '(launchers: the group; empty: min_observers alone counts)', live=True),
    'action_sender': Spec('', 'node whose actions are applied, e.g. /policy (empty: the only '
                          'action publisher at step 0); others are refused (docs/security.md)'),
    'log_every': Spec(0, 'log step, episode and context every N steps (0: never)',
                      live=True, low=0),
    'expected_rate': Spec(0.0, "/diagnostics: steps per second expected (0: the task's control "
                          'rate, realtime: control_rate); slower by more than rate_tolerance: '
                          'WARN', live=True, low=0.0, safety=True),
    'rate_tolerance': Spec(0.1, '/diagnostics: fraction the rate may fall short of (realtime: '
                           'also exceed) expected_rate', live=True, low=0.0, high=1.0,
                           safety=True),
    **latency_specs(0.0, 0.0, 'observation -> action', 'one control period',
                    'five control periods'),
    **LOCK_SPECS,
}
WARN_COUNTS = ('timeouts', 'rejected', 'stale', 'unexpected', 'foreign')
"""Counted faults that WARN while they grow (health.WINDOW_S), then clear."""


class SimBridgeNode(Node):
    """Steps a ScheduledEnv and speaks the step protocol of DESIGN.md."""

    def __init__(self, **node_options: Any) -> None:
        """`node_options` go to rclpy's Node (cli_args, context): one process can hold several."""
        super().__init__('sim_bridge', **node_options)
        self.params = declare_specs(self, SPECS, open_prefixes=[SCHEDULE_PREFIX])
        try:
            task = make_task(self.params['task'], seed=self.params['seed'])
        except ValueError as error:
            raise ValueError(f'sim_bridge: parameter task: {error}') from None
        self.params['task'] = task.name  # a task file's declared name, as steps carry it
        set_device(self, f'sim:{task.name}')  # /diagnostics hardware_id: <namespace>/sim:<task>
        schedule = schedule_from_config(self._schedule_config(), task, self.params['seed'])
        self.env = ScheduledEnv(task, schedule)
        self.mode: str = self.params['mode']
        self.exit_code = 0
        self.finished = False  # max_steps reached: run_nodes ends the spin (spin.py)
        self.counts = dict.fromkeys(
            ('steps', 'ok', 'clipped', 'rejected', 'timeouts', 'stale', 'unexpected', 'foreign',
             'resets'),
            0
        )
        self._rate = RateMeter()
        # Observation -> action as the simulator sees it: StepFeedback k out to Action k in.
        self._latency = LatencyMeter()
        self._sent: tuple[int, float] | None = None  # (step, monotonic time) not yet answered
        self._awaiting: int | None = None
        self._deadline = math.inf
        self._newest_action: tuple[float, Action] | None = None
        self._started = False
        self._start_after = math.inf

        qos = publisher_qos(self.mode)
        self._pub_state = self.create_publisher(StateVector, TOPICS.STATE, qos)
        self._pub_step = self.create_publisher(StepFeedback, TOPICS.STEP, qos)
        self._pub_truth = self.create_publisher(ContextTruth, TOPICS.CONTEXT_TRUTH, qos)
        self._pub_clock = self.create_publisher(Clock, TOPICS.CLOCK, qos)
        self._pub_image = None
        if self.params['pixels']:
            from sensor_msgs.msg import Image

            self._pub_image = self.create_publisher(Image, TOPICS.IMAGE, image_qos(self.mode))
        from diagnostic_msgs.msg import DiagnosticArray

        self._pub_diag = self.create_publisher(DiagnosticArray, TOPICS.DIAGNOSTICS, 10)
        self._window = WindowCounts()
        self._clock_watch = ClockWatch(self, own=self._pub_clock)
        handshake_of(self)  # the start hello: how a restart of this node is told apart
        # Only the paired sender's actions get through (by publisher GID); a deep reader
        # history keeps its action while a flood from elsewhere is drained and counted.
        self._senders = SenderPairing(self, self.resolve_topic_name(TOPICS.ACTION),
                                      self.params['action_sender'], what='actions')
        self._sub_action = SenderSubscription(self, Action, TOPICS.ACTION,
                                              step_qos(depth=ACTION_BACKLOG), self._on_action,
                                              admit=self._senders.accepts)
        self._period = self._control_period(task)
        tick = self._period if self.mode == 'realtime' else 0.005
        # Steady clocks: with use_sim_time, ROS time only moves once we publish /clock.
        # Lockstep polls every 5 ms only until step 0; then the same timer is the action
        # deadline, re-armed by every step (_publish), so it fires only for an overdue action.
        self._tick = steady_timer(self, tick, self._on_tick)
        steady_timer(self, 1.0, self._publish_diagnostics)
        handshake_of(self).urgent = self._publish_diagnostics  # a refused hello: ERROR at once
        self._wait_report = WaitReport(self)
        self._check_live(self.params)
        self._live = serve_live_changes(self, SPECS, self.params, lambda _changed: None,
                                        check=self._check_live)
        serve_trigger(self, 'reset_episode', self._reset_episode)
        self.get_logger().info(
            f'{self.params["task"]} in {self.mode} mode, contexts {list(task.context_names)}, '
            f'pixels={self.params["pixels"]}; waiting for peers on {self._sub_action.topic_name}'
            if self.params['wait_for_peers'] else f'{self.params["task"]} in {self.mode} mode'
        )

    # -- parameters -------------------------------------------------------------------------
    def _check_live(self, values: dict[str, Any]) -> None:
        """A nonzero stale_action_age below STALE_PERIODS periods would make most steps safe."""
        age = values['stale_action_age']
        if self.mode == 'realtime' and 0 < age < STALE_PERIODS * self._period:
            raise ValueError(f'sim_bridge: parameter stale_action_age must be 0 or >= '
                             f'{STALE_PERIODS * self._period:g} s ({STALE_PERIODS} control '
                             f'periods), got {age}')

    def _schedule_config(self) -> dict[str, Any]:
        """Collect the `schedule.*` parameters into the plain dict the schedule code reads."""
        config: dict[str, Any] = {}
        for name, parameter in self._parameters.items():
            if name.startswith(SCHEDULE_PREFIX):
                value = parameter.value
                if not isinstance(value, (str, bytes)) and hasattr(value, '__len__'):
                    value = list(value)  # ROS array parameters come as array.array
                config[name[len(SCHEDULE_PREFIX):]] = value
        return config or {'kind': 'constant'}

    def _control_period(self, task: Any) -> float:
        """Wall-clock period of one agent step in realtime mode."""
        if self.params['control_rate'] > 0:
            return 1.0 / self.params['control_rate']
        return float(task.agent_period)

    # -- step protocol ----------------------------------------------------------------------
    def _peers_ready(self) -> bool:
        """True once a policy publishes actions, someone observes, and DDS matched them all."""
        if not self.params['wait_for_peers']:
            return True
        outputs = [self._pub_step, self._pub_state]
        if self._pub_image is not None:
            outputs.append(self._pub_image)
        missing = missing_peers(self, outputs, self._sub_action, self.params['min_observers'],
                                others=[self._pub_truth, self._pub_clock],
                                named=self.params['observers'])
        if missing:
            self._wait_report.waiting('; '.join(missing))
        return not missing

    def _on_tick(self) -> None:
        if self.finished:
            return
        now = time.monotonic()
        if not self._started:
            if math.isinf(self._start_after) and self._peers_ready():
                self._start_after = now + self.params['peer_grace']
            if now >= self._start_after:
                if not self._peers_ready() or not self._pair_sender():
                    self._start_after = math.inf  # someone appeared during the grace period
                    return
                self._started = True
                self._publish(self.env.reset())
            return
        if self.mode == 'realtime':
            self._realtime_step(now)
        elif self._awaiting is not None and now >= self._deadline:
            self.counts['timeouts'] += 1
            self.get_logger().warning(
                f'no action for step {self._awaiting} within {self.params["action_timeout"]} s: '
                'applying the safe action (counted as a timeout)',
                throttle_duration_sec=5.0,
            )
            self._advance(None)

    def _reset_episode(self) -> str:
        """~/reset_episode: the episode ends at the next step, counted as `resets`."""
        if not self.env.end_episode():
            raise ValueError('no episode to end: not stepping yet, or this one ends anyway')
        self.counts['resets'] += 1
        return (f'episode {self.env.episode} ends at the next step (step '
                f"{self.env.step_index + 1} is the next episode's reset)")

    def _pair_sender(self) -> bool:
        """Pair with the one action publisher (or action_sender) before step 0."""
        if not self.params['wait_for_peers'] or self._senders.paired is not None:
            return True
        named = len(self._senders.publishers())
        matched = self._sub_action.get_publisher_count()
        # DDS may have matched a publisher the ROS graph cannot name yet: wait for its name.
        problem = f'the ROS graph to name all {matched} publishers of {self._senders.topic}' \
            if matched > named else self._senders.pair(settle=PAIRING_SETTLE_S)
        if problem is not None:
            self._wait_report.waiting(problem)
        return problem is None

    def _on_action(self, msg: Action) -> None:
        if self._sent is not None and msg.step == self._sent[0]:
            self._latency.add(time.monotonic() - self._sent[1])
            self._sent = None
        if self.mode == 'realtime':
            self._newest_action = (time.monotonic(), msg)
            return
        if self._awaiting is None or msg.step != self._awaiting:
            self.counts['unexpected'] += 1
            self.get_logger().warning(
                f'dropped action for step {msg.step}: waiting for step {self._awaiting}',
                throttle_duration_sec=5.0,
            )
            return
        self._advance(np.asarray(msg.data, dtype=np.float64))

    def _realtime_step(self, now: float) -> None:
        max_age = self.params['stale_action_age'] or 3 * self._period
        action = None
        if self._newest_action is not None:
            received, msg = self._newest_action
            if now - received <= max_age:
                action = np.asarray(msg.data, dtype=np.float64)
        if action is None:  # nothing recent enough: the safe action, counted as stale
            self.counts['stale'] += 1
        self._advance(action, stale=action is None)

    def _advance(self, action: np.ndarray | None, stale: bool = False) -> None:
        """Apply one action (None: the safe action) and publish the next step."""
        max_steps = self.params['max_steps']
        if max_steps and self.counts['steps'] > max_steps:
            # Observation max_steps got its answer: the loop is complete, stop here.
            if not self.finished:
                self.get_logger().info(f'max_steps={max_steps} reached; counts {self.counts}; '
                                       f'{self._latency.summary()}')
            self._started = False  # said all there is to say
            self.finished = True  # not NodeFinished: the events executor logs what it raises
            return
        result = self.env.step(action)
        if stale and result.status == ActionStatus.TIMEOUT:
            result = result.with_status(ActionStatus.STALE)
        self._count(result)
        self._publish(result)

    def _count(self, result: EnvStep) -> None:
        if result.status == ActionStatus.OK:
            self.counts['ok'] += 1
        elif result.status == ActionStatus.CLIPPED:
            self.counts['clipped'] += 1
            self.get_logger().info(f'step {result.step}: {result.reason}',
                                   throttle_duration_sec=5.0)
        elif result.status == ActionStatus.REJECTED:
            self.counts['rejected'] += 1
            self.get_logger().warning(f'step {result.step}: {result.reason}',
                                      throttle_duration_sec=1.0)

    def _publish(self, result: EnvStep) -> None:
        """Publish everything of step k with one stamp; then wait for Action k."""
        stamp = stamp_from_seconds(result.sim_time)
        task_name = self.params['task']
        self._pub_clock.publish(Clock(clock=stamp))
        truth = ContextTruth()
        truth.header.stamp = stamp
        truth.step = result.step
        names = list(result.observation.context)
        truth.names = names
        truth.values = [float(result.observation.context[n]) for n in names]
        truth.segment = result.segment
        self._pub_truth.publish(truth)
        if self._pub_image is not None:
            size = self.params['image_size']
            frame = self.env.task.render(size, size)
            self._pub_image.publish(image_from_array(frame, stamp))
        feedback = StepFeedback()
        feedback.header.stamp = stamp
        feedback.step = result.step
        feedback.episode = result.episode
        feedback.episode_step = result.episode_step
        feedback.first = result.observation.first
        feedback.last = result.observation.last
        feedback.reward = float(result.observation.reward)
        feedback.applied_action = (
            [] if result.applied_action is None
            else result.applied_action.astype(np.float32).tolist()
        )
        feedback.action_status = int(result.status)
        feedback.task = task_name
        self._sent = (result.step, time.monotonic())
        self._pub_step.publish(feedback)
        # Counted once its StepFeedback is out: a Ctrl-C that stops the publishing below still
        # leaves `close()` naming the last step a recording holds.
        self.counts['steps'] += 1
        state = StateVector()
        state.header.stamp = stamp
        state.step = result.step
        state.data = result.observation.state.astype(np.float64).tolist()
        # The state goes last: a consumer that acts on o_k has c_k, r_k and the frame already.
        self._pub_state.publish(state)
        self._rate.tick()
        every = self.params['log_every']
        if every and result.step % every == 0:
            self.get_logger().info(
                f'step {result.step} episode {result.episode} context {result.observation.context}'
            )
        self._awaiting = result.step
        self._deadline = time.monotonic() + self.params['action_timeout']
        if self.mode == 'lockstep':  # deadline first: the timer cannot fire before it
            self._tick.timer_period_ns = int(self.params['action_timeout'] * 1e9)
            self._tick.reset()

    def _publish_diagnostics(self) -> None:
        self.counts['foreign'] = self._senders.refused
        self.counts['before_hello'] = self._senders.before_hello
        values = {'mode': self.mode, 'task': self.params['task'],
                  'rate_hz': f'{self._rate.rate:.1f}', 'action_sender': str(self._senders.paired),
                  **self._latency.diagnostics_values(), **self.counts,
                  **self._live.values()}
        problems, errors = self._checks(float(values['latency_p99_ms']))
        problems = [*problems, *self._live.problems()]
        self._pub_diag.publish(diagnostics_message(self, 'step loop', values, problems, errors))

    def _checks(self, p99_ms: float) -> tuple[list[str], list[str]]:
        """(WARN, ERROR) lines: faults of the window, rate, latency, other senders and clocks."""
        grown = self._window.delta(self.counts)
        problems = self._window.problems(grown, WARN_COUNTS)
        period = self._period if self.mode == 'realtime' else self.env.task.agent_period
        expected = self.params['expected_rate'] or 1.0 / period
        warn, error = rate_problems(self._rate.rate, grown['steps'], expected,
                                    self.params['rate_tolerance'], self._started,
                                    upper=self.mode == 'realtime')
        slow, late = latency_problems(p99_ms, self.params['latency_warn_ms'] or period * 1e3,
                                      self.params['latency_error_ms'] or 5 * period * 1e3,
                                      'observation -> action')
        errors = [*self._senders.errors(), *self._clock_watch.errors(), *error, *late]
        return [*problems, *warn, *slow], errors

    def destroy_node(self) -> None:
        """The action subscription is ours (not rclpy's): it goes before the node."""
        self._sub_action.destroy()
        super().destroy_node()

    def close(self) -> None:
        """Release the renderer; say how far the loop got (what a recording should hold)."""
        self.env.task.close()
        if self._started:
            self.get_logger().info(f'stopped after step {self.counts["steps"] - 1}; '
                                   f'counts {self.counts}; {self._latency.summary()}')


def main(args: list[str] | None = None) -> int:
    """Entry point of `ros2 run zeus_ros sim_bridge_node`."""
    return run_node(SimBridgeNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
