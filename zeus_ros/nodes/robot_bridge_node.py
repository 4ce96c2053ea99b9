"""robot_bridge node: a robot's JointState and command topics, spoken as our step protocol.

It takes sim_bridge's place in realtime mode. On a fixed control-rate timer it assembles step k
from the newest JointState (the `joints` of the params, in that order; positions, velocities,
efforts as `observe` says) and the extra Float64MultiArray inputs (and republishes the newest
camera frame, square and resized, for pixel agents), computes the reward of the
params (a built-in or `package.module:function`), and publishes StateVector, StepFeedback and
ContextTruth (the operator-declared `context`) with one stamp. The policy's Action goes to the
robot at once, converted to Float64MultiArray / JointTrajectory / Twist in the controller's
joint order: clipped to the limits; NaN or a wrong length rejected; none fresh enough -> the
configured safe command. Every one of these, and late or missing inputs, is counted and
reported on /diagnostics and in StepFeedback.action_status.
"""

from __future__ import annotations

from functools import partial
import math
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Float64MultiArray
from zeus_msgs.msg import Action, ContextTruth, StateVector, StepFeedback

from sim_bridge.actions import ActionStatus, check_action
from sim_bridge.rewards import JointObservation, load_reward
from sim_bridge.robot import RobotSpec, parse_context
from zeus_ros.nodes.diagnostics import set_device
from zeus_ros.nodes.handshake import handshake_of
from zeus_ros.nodes.health import (
    ClockWatch,
    WindowCounts,
    latency_problems,
    latency_specs,
    rate_problems,
)
from zeus_ros.nodes.messages import diagnostics_message, image_from_array
from zeus_ros.nodes.meters import LatencyMeter, RateMeter
from zeus_ros.nodes.params import LOCK_SPECS, Spec, declare_specs, serve_live_changes
from zeus_ros.nodes.peers import WaitReport, missing_peers, steady_timer
from zeus_ros.nodes.robot_io import (
    COMMAND_TYPES,
    CommandPublisher,
    frame_from_camera,
    hold_positions,
    parse_safe_command,
    read_joint_state,
)
from zeus_ros.nodes.senders import PAIRING_SETTLE_S, SenderPairing, SenderSubscription
from zeus_ros.nodes.spin import run_node
from zeus_ros.nodes.topics import TOPICS, image_qos, step_qos

MIN_PERIODS = 2
"""A nonzero input_timeout or stale_action_age must span at least this many control periods:
shorter, and most steps would send the safe command."""

SPECS: dict[str, Spec] = {
    'task': Spec('', "the robot's task name, written into every step (bags and checkpoints "
                 'carry it)', required=True),
    'joints': Spec([''], 'JointState names to observe, in observation order'),
    'observe': Spec(['position', 'velocity'], 'JointState fields to observe: position, '
                    'velocity, effort (in that layout order)'),
    'joint_state_topic': Spec('joint_states', 'sensor_msgs/JointState input'),
    'extra_inputs': Spec([''], "extra Float64MultiArray inputs as 'TOPIC:SIZE', appended to "
                         'the observation in this order'),
    'image_topic': Spec('', 'a camera (sensor_msgs/Image, rgb8/bgr8/rgba8/bgra8/mono8) '
                        'republished per step on zeus/observation/image for pixel agents '
                        "('': none)"),
    'image_size': Spec(84, 'side of the square frame republished (centre crop, nearest pixel)',
                       low=1, high=1024),
    'control_rate': Spec(50.0, 'control steps per second (wall clock)', low=0.1, high=1000.0),
    'input_timeout': Spec(0.0, 'an input older than this skips the step and sends the safe '
                          'command (0: 5 control periods)', live=True, low=0.0, safety=True,
                          allowed=f'0, or at least {MIN_PERIODS} control periods'),
    'episode_length': Spec(1000, 'steps per episode (the history is cleared between)', low=1),
    'reward': Spec('', 'velocity:JOINT, tracking:JOINT=TARGET,... or package.module:function',
                   required=True),
    'action_joints': Spec([''], "joints (or axes) the policy's action drives, in action order"),
    'action_low': Spec([0.0], 'lower limit of each action value (clipped)'),
    'action_high': Spec([0.0], 'upper limit of each action value (clipped)'),
    'command_type': Spec('float64_multi_array', 'command message', choices=COMMAND_TYPES),
    'command_topic': Spec('forward_command_controller/commands', 'command output topic'),
    'command_joints': Spec([''], "the controller's joint order (empty: action_joints)"),
    'twist_fields': Spec([''], 'twist(_stamped): the field each action value sets, e.g. '
                         "['linear.x', 'angular.z']"),
    'safe_command': Spec('', "sent when no usable action: '' (zeros clipped into the limits), "
                         "'hold' (measured positions) or comma-separated values"),
    'action_sender': Spec('', 'node whose actions drive the robot, e.g. /policy (empty: the only '
                          'action publisher at step 0); others are refused (docs/security.md)'),
    'stale_action_age': Spec(0.0, 'an older action is replaced by the safe command '
                             '(0: 3 control periods)', live=True, low=0.0, safety=True,
                             allowed=f'0, or at least {MIN_PERIODS} control periods'),
    'context': Spec('', "known context as 'NAME=VALUE,...' (e.g. the payload you mounted), "
                    'published as the true context; values live, names fixed', live=True,
                    safety=True),
    'max_steps': Spec(0, 'stop after this many steps (0: run until stopped)', live=True, low=0,
                      safety=True),
    'wait_for_peers': Spec(True, 'start once a policy publishes actions and someone observes'),
    'peer_grace': Spec(0.5, 'seconds between seeing the peers and publishing step 0',
                       live=True, low=0.0),
    'min_observers': Spec(0, 'wait for this many zeus/step subscribers before step 0',
                          live=True, low=0),
    'observers': Spec([''], 'names of the nodes that must subscribe to zeus/step before step 0 '
                      '(launchers: the group; empty: min_observers alone counts)', live=True),
    'log_every': Spec(0, 'log step and episode every N steps (0: never)', live=True, low=0),
    'rate_tolerance': Spec(0.1, '/diagnostics: fraction the step rate may miss control_rate by '
                           'before it WARNs', live=True, low=0.0, high=1.0, safety=True),
    **latency_specs(0.0, 0.0, 'observation -> action', 'one control period',
                    'five control periods'),
    **LOCK_SPECS,
}
COUNTS = ('steps', 'ok', 'clipped', 'rejected', 'stale', 'late_inputs', 'missing_inputs',
          'rejected_inputs', 'bad_rewards', 'foreign')
ACTION_BACKLOG = 1000  # reader history of zeus/action, as sim_bridge: room for a flood


class RobotBridgeNode(Node):
    """Turns robot topics into the step protocol and actions into robot commands."""

    def __init__(self, **node_options: Any) -> None:
        """`node_options` go to rclpy's Node (cli_args, context): one process can hold several."""
        super().__init__('robot_bridge', **node_options)
        self.params = declare_specs(self, SPECS)
        self.spec = RobotSpec.from_params(self.params)
        set_device(self, f'robot:{self.spec.task}')  # hardware_id: <namespace>/robot:<task>
        self.reward_fn = load_reward(self.params['reward'], self.spec.joints, self.spec.observe)
        self.low, self.high = self.spec.action_low, self.spec.action_high
        self.safe = parse_safe_command(self.params['safe_command'], self.low, self.high)
        self.period = 1.0 / self.params['control_rate']
        self.counts = dict.fromkeys(COUNTS, 0)
        self._rate = RateMeter()
        # How late the policy answers: StepFeedback k out to Action k in (/diagnostics, log).
        self._latency = LatencyMeter()
        self._sent: tuple[int, float] | None = None  # (step, monotonic time) not yet answered
        self._joints: tuple[float, dict[str, dict[str, float]]] | None = None
        self._positions: dict[str, float] = {}
        self._extras: dict[str, tuple[float, np.ndarray]] = {}
        self._image: tuple[float, Image] | None = None
        self._applied: tuple[float, np.ndarray, ActionStatus] | None = None
        self._action_time = -math.inf
        self._hold: np.ndarray | None = None
        self._prev: JointObservation | None = None
        self._step = -1
        self._episode = -1
        self._episode_step = 0
        self._new_episode = True
        self._segment = 0
        self._known_context = dict(self.spec.context)
        self._started = False
        self.finished = False  # max_steps reached: run_nodes ends the spin (spin.py)
        self._start_after = math.inf

        self.command = CommandPublisher(
            self, self.params['command_type'], self.params['command_topic'],
            self.spec.action_joints, [j for j in self.params['command_joints'] if j],
            [f for f in self.params['twist_fields'] if f], self.period)
        self.create_subscription(JointState, self.params['joint_state_topic'],
                                 self._on_joint_state, qos_profile_sensor_data)
        for topic, size in self.spec.extra_inputs:
            self.create_subscription(Float64MultiArray, topic,
                                     partial(self._on_extra, topic, size),
                                     qos_profile_sensor_data)
        self._pub_image = None
        if self.params['image_topic']:
            self.create_subscription(Image, self.params['image_topic'], self._on_image,
                                     qos_profile_sensor_data)
            self._pub_image = self.create_publisher(Image, TOPICS.IMAGE, image_qos('realtime'))
        qos = step_qos()
        self._pub_step = self.create_publisher(StepFeedback, TOPICS.STEP, qos)
        self._pub_truth = self.create_publisher(ContextTruth, TOPICS.CONTEXT_TRUTH, qos)
        self._pub_state = self.create_publisher(StateVector, TOPICS.STATE, qos)
        self._pub_diag = self.create_publisher(DiagnosticArray, TOPICS.DIAGNOSTICS, 10)
        self._window = WindowCounts()
        self._clock_watch = ClockWatch(self)
        handshake_of(self)  # the start hello: how a restart of this node is told apart
        # Only the paired policy drives the robot (by publisher GID, as sim_bridge does); a deep
        # reader history keeps its action while a flood from elsewhere is drained and counted.
        self._senders = SenderPairing(self, self.resolve_topic_name(TOPICS.ACTION),
                                      self.params['action_sender'], what='actions')
        self._sub_action = SenderSubscription(self, Action, TOPICS.ACTION,
                                              step_qos(depth=ACTION_BACKLOG), self._on_action,
                                              admit=self._senders.accepts)
        self._wait_report = WaitReport(self)
        steady_timer(self, self.period, self._on_tick)
        steady_timer(self, 1.0, self._publish_diagnostics)
        handshake_of(self).urgent = self._publish_diagnostics  # a refused hello: ERROR at once
        self._check_periods(self.params)
        self._live = serve_live_changes(self, SPECS, self.params, self._apply_live,
                                        check=self._check_live)
        self.get_logger().info(
            f'{self.spec.task}: {len(self.spec.joints)} joints x {list(self.spec.observe)} + '
            f'{len(self.spec.extra_inputs)} extra input(s) = {self.spec.state_dim} values at '
            f'{self.params["control_rate"]:g} Hz; actions {list(self.spec.action_joints)} -> '
            f'{self.params["command_type"]} on {self.command.publisher.topic_name}')

    # -- parameters -------------------------------------------------------------------------
    def _check_live(self, values: dict[str, Any]) -> None:
        names = set(parse_context(values['context']))
        if names != set(self.spec.context):
            raise ValueError(f'robot_bridge: context names are fixed at start '
                             f'({sorted(self.spec.context)}); only values change live')
        self._check_periods(values)

    def _check_periods(self, values: dict[str, Any]) -> None:
        """A nonzero input_timeout or stale_action_age of fewer than MIN_PERIODS periods."""
        for key in ('input_timeout', 'stale_action_age'):
            if 0 < values[key] < MIN_PERIODS * self.period:
                raise ValueError(f'robot_bridge: parameter {key} must be 0 or >= '
                                 f'{MIN_PERIODS * self.period:g} s ({MIN_PERIODS} control '
                                 f'periods), got {values[key]}')

    def _apply_live(self, changed: dict[str, Any]) -> None:
        if 'context' in changed:
            context = parse_context(changed['context'])
            if context != self._known_context:
                self._known_context = context
                self._segment += 1

    # -- inputs -----------------------------------------------------------------------------
    def _reject_input(self, topic: str, error: ValueError) -> None:
        self.counts['rejected_inputs'] += 1
        self.get_logger().warning(f'rejected {topic}: {error}', throttle_duration_sec=2.0)

    def _on_joint_state(self, msg: JointState) -> None:
        try:
            values = read_joint_state(msg, self.spec.joints, self.spec.observe)
        except ValueError as error:
            self._reject_input(self.params['joint_state_topic'], error)
            return
        self._joints = (time.monotonic(), values)
        if len(msg.position) == len(msg.name):
            self._positions = dict(zip(msg.name, map(float, msg.position), strict=True))

    def _on_extra(self, topic: str, size: int, msg: Float64MultiArray) -> None:
        data = np.asarray(msg.data, dtype=np.float64)
        if data.shape != (size,) or not np.all(np.isfinite(data)):
            self._reject_input(topic, ValueError(
                f'expected {size} finite values, got {data.size}: {data.tolist()[:8]}'))
            return
        self._extras[topic] = (time.monotonic(), data)

    def _on_image(self, msg: Image) -> None:
        self._image = (time.monotonic(), msg)

    def _on_action(self, msg: Action) -> None:
        self._action_time = time.monotonic()
        if self._sent is not None and msg.step == self._sent[0]:
            self._latency.add(self._action_time - self._sent[1])
            self._sent = None
        checked = check_action(msg.data, self.low, self.high)
        self.counts[{ActionStatus.OK: 'ok', ActionStatus.CLIPPED: 'clipped'}.get(
            checked.status, 'rejected')] += 1
        if checked.status == ActionStatus.REJECTED:
            self.get_logger().warning(f'action for step {msg.step}: {checked.reason}',
                                      throttle_duration_sec=1.0)
            self._send_safe(ActionStatus.REJECTED)
            return
        self._hold = None
        self.command.publish(checked.applied)
        self._applied = (time.monotonic(), checked.applied, checked.status)

    def _send_safe(self, status: ActionStatus) -> None:
        """Send the safe command (for 'hold': where the joints were when it began)."""
        command = self.safe
        if isinstance(command, str):
            if self._hold is None:
                self._hold = hold_positions(self._positions, self.spec.action_joints)
            held = self._hold if self._hold is not None else np.zeros_like(self.low)
            command = np.clip(held, self.low, self.high)
        self.command.publish(command)
        self._applied = (time.monotonic(), command, status)

    # -- the control loop -------------------------------------------------------------------
    def _inputs_missing(self, now: float) -> list[str]:
        """Inputs never seen or older than input_timeout (the step cannot be built)."""
        timeout = self.params['input_timeout'] or 5 * self.period
        ages = {self.params['joint_state_topic']: self._joints[0] if self._joints else None}
        ages.update({topic: self._extras[topic][0] if topic in self._extras else None
                     for topic, _ in self.spec.extra_inputs})
        if self._pub_image is not None:
            ages[self.params['image_topic']] = self._image[0] if self._image else None
        return [topic for topic, seen in ages.items() if seen is None or now - seen > timeout]

    def _ready(self, now: float) -> bool:
        missing = self._inputs_missing(now)
        if self.params['wait_for_peers']:
            outputs = [self._pub_step, self._pub_state]
            if self._pub_image is not None:
                outputs.append(self._pub_image)
            missing += missing_peers(self, outputs, self._sub_action,
                                     self.params['min_observers'], others=[self._pub_truth],
                                     named=self.params['observers'])
            if not missing and self._senders.paired is None:
                problem = self._senders.pair(settle=PAIRING_SETTLE_S)
                missing += [problem] if problem else []
        if missing:
            self._wait_report.waiting('; '.join(missing))
        return not missing

    def _on_tick(self) -> None:
        if self.finished:
            return
        now = time.monotonic()
        if not self._started:
            if math.isinf(self._start_after) and self._ready(now):
                self._start_after = now + self.params['peer_grace']
            if now >= self._start_after:
                if not self._ready(now):
                    self._start_after = math.inf
                    return
                self._started = True
                self._action_time = now  # the stale clock starts with step 0
                self._send_safe(ActionStatus.NONE)
                self.get_logger().info('inputs and peers ready: stepping')
                self._publish_step(now)
            return
        max_steps = self.params['max_steps']
        if max_steps and self.counts['steps'] > max_steps:
            self._send_safe(ActionStatus.NONE)
            self.get_logger().info(f'max_steps={max_steps} reached; counts {self.counts}')
            self._started = False
            self.finished = True  # not NodeFinished: the events executor logs what it raises
            return
        max_age = self.params['stale_action_age'] or 3 * self.period
        if now - self._action_time > max_age:
            self.counts['stale'] += 1
            self.get_logger().warning('no fresh action: safe command sent (counted as stale)',
                                      throttle_duration_sec=2.0)
            self._send_safe(ActionStatus.STALE)
        missing = self._inputs_missing(now)
        if missing:
            self.counts['missing_inputs'] += 1
            self.get_logger().warning(f'no recent {missing}: step skipped, safe command sent, '
                                      'the episode restarts when they return',
                                      throttle_duration_sec=2.0)
            self._send_safe(ActionStatus.STALE)
            self._new_episode = True
            return
        self._publish_step(now)

    def _observe(self, now: float) -> JointObservation:
        """The observation from the newest inputs (held); one older than 1.5 periods is late."""
        assert self._joints is not None
        received = [self._joints[0], *(self._extras[t][0] for t, _ in self.spec.extra_inputs)]
        if self._image is not None:
            received.append(self._image[0])
        self.counts['late_inputs'] += sum(now - seen > 1.5 * self.period for seen in received)
        extras = {topic: self._extras[topic][1] for topic, _ in self.spec.extra_inputs}
        return self.spec.observation(self._joints[1], extras)

    def _reward(self, obs: JointObservation, action: np.ndarray) -> float:
        try:
            reward = float(self.reward_fn(obs, action, self._prev))
        except Exception as error:
            reward = math.nan
            self.get_logger().error(f'reward {self.params["reward"]} raised {error!r}',
                                    throttle_duration_sec=2.0)
        if not math.isfinite(reward):
            self.counts['bad_rewards'] += 1
            return 0.0
        return reward

    def _publish_step(self, now: float) -> None:
        """Publish StepFeedback, ContextTruth and StateVector of step k with one stamp."""
        obs = self._observe(now)
        first = self._new_episode
        assert self._applied is not None
        _, applied, status = self._applied
        self._step += 1
        if first:
            self._episode += 1
            self._episode_step = 0
        else:
            self._episode_step += 1
        last = self._episode_step >= self.params['episode_length']
        self._new_episode = last
        stamp = self.get_clock().now().to_msg()
        truth = ContextTruth(step=self._step, names=list(self._known_context),
                             values=[float(v) for v in self._known_context.values()],
                             segment=self._segment)
        truth.header.stamp = stamp
        self._pub_truth.publish(truth)
        feedback = StepFeedback(
            step=self._step, episode=self._episode, episode_step=self._episode_step,
            first=first, last=last, task=self.spec.task,
            reward=0.0 if first else self._reward(obs, applied),
            applied_action=[] if first else applied.astype(np.float32).tolist(),
            action_status=int(ActionStatus.NONE if first else status))
        feedback.header.stamp = stamp
        self._sent = (self._step, time.monotonic())
        self._pub_step.publish(feedback)
        if self._pub_image is not None and self._image is not None:
            self._publish_frame(self._image[1], stamp)
        state = StateVector(step=self._step, data=obs.state.tolist())
        state.header.stamp = stamp
        self._pub_state.publish(state)  # last: whoever acts on o_k has r_k and c_k already
        self._prev = obs
        self.counts['steps'] += 1
        self._rate.tick()
        every = self.params['log_every']
        if every and self._step % every == 0:
            self.get_logger().info(f'step {self._step} episode {self._episode}')

    def _publish_frame(self, msg: Image, stamp: Any) -> None:
        """The camera frame of this step, converted, with the step's stamp (a bad one: counted)."""
        try:
            frame = frame_from_camera(msg, self.params['image_size'])
        except ValueError as error:
            self._reject_input(self.params['image_topic'], error)
            return
        self._pub_image.publish(image_from_array(frame, stamp))

    def _publish_diagnostics(self) -> None:
        self.counts['foreign'] = self._senders.refused
        self.counts['before_hello'] = self._senders.before_hello
        values = {'task': self.spec.task, 'rate_hz': f'{self._rate.rate:.1f}',
                  'action_sender': str(self._senders.paired),
                  **self._latency.diagnostics_values(), **self.counts, **self._live.values()}
        grown = self._window.delta(self.counts)
        problems = [*self._window.problems(grown, COUNTS[3:]), *self._live.problems()]
        warn, stalled = rate_problems(self._rate.rate, grown['steps'],
                                      self.params['control_rate'], self.params['rate_tolerance'],
                                      self._started, upper=True)
        ms = self.period * 1e3
        slow, late = latency_problems(float(values['latency_p99_ms']),
                                      self.params['latency_warn_ms'] or ms,
                                      self.params['latency_error_ms'] or 5 * ms,
                                      'observation -> action')
        errors = [*self._senders.errors(), *self._clock_watch.errors(), *stalled, *late]
        self._pub_diag.publish(diagnostics_message(self, 'robot loop', values,
                                                   [*problems, *warn, *slow], errors))

    def close(self) -> None:
        """Say how far the loop got."""
        if self._started:
            self.get_logger().info(f'stopped after step {self._step}; counts {self.counts}; '
                                   f'{self._latency.summary()}')


def main(args: list[str] | None = None) -> int:
    """Entry point of `ros2 run zeus_ros robot_bridge_node`."""
    return run_node(RobotBridgeNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
