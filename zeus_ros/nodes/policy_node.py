"""policy node: acts on observation k and context k, and never waits forever for a context.

Action k answers observation k (same step, same stamp). When context k is late beyond
`context_deadline` it acts on the newest context it has and counts the step as stale; with no
context at all for `context_timeout` seconds it publishes the task's safe action. Without a
checkpoint it is a seeded uniform-random policy (for data collection and demos).
With `context_lag` L > 0 it acts on observation k with context k - L (never one from before
the episode's first step, nor from before its first context since start or redeploy: those
never come) instead of waiting for context k: the estimator works beside the
policy rather than before it, off the step's critical path, at the price of a context L
steps old (`experiments/context_lag.py` measures that price in-process; `zeus collect
--context-lag L` acts the same way).

It acts only on estimates stamped with its own checkpoint's sha256: while a live redeploy has
reached one of the pair but not the other, estimates are refused (counted as `mismatched`) and
the safe action goes out instead. Steps and observations come from its bridge only, contexts from
its estimator only (paired by publisher GID and node name: `step_source`, `context_source`;
senders.py): any other publisher is refused unread and an ERROR on /diagnostics.

Operator services (services.py): `~/freeze_context` (std_srvs/SetBool) sets `frozen_context`
to the checkpoint's train-mean context (else the newest estimate), or back to live;
`~/stage_checkpoint` (zeus_msgs/SwapCheckpoint) loads a checkpoint that the policy switches to
at the first estimate stamped with its sha256: the policy's half of the atomic pair swap
(pair_swap.py; continual_trainer ~/swap_checkpoint).
"""

from __future__ import annotations

import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rclpy.parameter import Parameter
from zeus_msgs.msg import Action, ContextEstimate, StepFeedback

from zeus_ros.learning.inference import MAX_CONTEXT_LAG, InferenceAgent
from zeus_ros.learning.readout import TRAIN_MEAN_KEY
from zeus_ros.nodes.agent_loader import LoadedAgent, check_swappable, load_inference_agent
from zeus_ros.nodes.assembler import StepParts
from zeus_ros.nodes.diagnostics import unwatch_peers
from zeus_ros.nodes.handshake import handshake_of
from zeus_ros.nodes.health import (
    ClockWatch,
    WindowCounts,
    latency_problems,
    latency_specs,
    rate_problems,
)
from zeus_ros.nodes.lifecycle import LIFECYCLE_SPECS, ManagedNode
from zeus_ros.nodes.messages import diagnostics_message
from zeus_ros.nodes.meters import LatencyMeter, RateMeter
from zeus_ros.nodes.observation import HEARD_SPECS, ObservationDecoder, StepInputs
from zeus_ros.nodes.params import LOCK_SPECS, Spec, declare_specs, serve_live_changes
from zeus_ros.nodes.peers import WaitReport, count_publishers, steady_timer
from zeus_ros.nodes.senders import SenderPairing, SenderSubscription
from zeus_ros.nodes.services import serve_swap, serve_switch
from zeus_ros.nodes.spin import run_node
from zeus_ros.nodes.topics import TOPICS, action_qos, step_qos

NOISE_MAX = 0.5
"""The most exploration noise (std as a fraction of half the action range): 0.5 already makes
every action noisy (test_ros_citizen); issue 49's 1.0 quadrupled the per-step loss."""
CONTEXT_TIMEOUT_FLOOR = 0.1
"""Seconds: the least context_timeout; below it a context a few steps late would make the
policy publish the safe action instead (as sim_bridge's ACTION_TIMEOUT_FLOOR)."""

SPECS: dict[str, Spec] = {
    'checkpoint': Spec('', 'checkpoint to act with (empty: seeded uniform-random policy); a '
                       'live change loads it (same task, observations and actions) and acts '
                       "only on estimates of the estimator's same checkpoint", live=True),
    'task': Spec('', 'task the checkpoint must be for (required without a checkpoint)'),
    'mode': Spec('lockstep', "sim_bridge's mode (sets the action QoS)",
                 choices=('lockstep', 'realtime')),
    'deterministic': Spec(True, "act with the actor's mean (false: sample)", live=True,
                          safety=True),
    'noise': Spec(0.0, 'exploration noise, a fraction of half the action range', live=True,
                  low=0.0, high=NOISE_MAX, safety=True),
    'seed': Spec(0, 'seeds sampling, noise and the random policy', low=0),
    'context_deadline': Spec(0.2, 'seconds to wait for context k before acting on the newest',
                             live=True, low=0.0, safety=True),
    'context_lag': Spec(0, 'act on observation k with context k - context_lag (from this '
                        "episode only) instead of waiting for context k: the estimator leaves "
                        "the step's critical path", live=True, low=0, high=MAX_CONTEXT_LAG,
                        safety=True),
    'context_timeout': Spec(2.0, 'no context for this long: publish the safe action',
                            live=True, low=CONTEXT_TIMEOUT_FLOOR, safety=True),
    'image_size': Spec(84, 'frame height and width in pixels', low=1, high=1024),
    'device': Spec('cpu', 'torch device'),
    'torch_threads': Spec(1, 'torch intra-op threads', low=1),
    'frozen_context': Spec('', 'comma-separated context values used at every step instead of '
                           'the live estimate (value of adaptation); empty: live context',
                           live=True, safety=True),
    'context_source': Spec('', 'node whose contexts are used, e.g. /r1/context_estimator '
                           '(empty: the only publisher of zeus/context at the first context); '
                           'any other is refused and an ERROR (docs/security.md)'),
    **HEARD_SPECS,
    **latency_specs(40.0, 200.0, 'observation -> action'),
    **LOCK_SPECS,
    **LIFECYCLE_SPECS,
}
WARN_COUNTS = ('stale', 'safe', 'rejected', 'mismatched', 'foreign')
"""Counted faults that WARN while they grow (health.WINDOW_S), then clear."""


class PolicyNode(ManagedNode):
    """Publishes Action k for observation k, conditioned on the context of step k.

    Managed (lifecycle.py): configure loads the checkpoint and subscribes to the steps and
    contexts; activate acts (the action publisher appears at the first activation and stays
    for the node's life, so sim_bridge's pairing holds across deactivate / activate);
    deactivate answers the observation still waiting for its context with the safe action,
    then publishes nothing: sim_bridge applies its own safe action after `action_timeout`.
    """

    def __init__(self, **node_options: Any) -> None:
        """`node_options` go to rclpy's Node (cli_args, context): one process can hold several."""
        super().__init__('policy', **node_options)
        self.params = declare_specs(self, SPECS)
        self.rng = np.random.default_rng(self.params['seed'])
        self.agent: InferenceAgent | None = None
        self.loaded: LoadedAgent | None = None
        self._pending: LoadedAgent | None = None
        self._staged: LoadedAgent | None = None  # used from its first estimate on
        self._adopting = ''  # the staged path, while set as `checkpoint` (no reload)
        self.needs_context = False
        self.frozen: np.ndarray | None = None
        # The data path: built by configure, let go of by cleanup (_release).
        self.inputs: StepInputs | None = None
        self._senders: SenderPairing | None = None
        self._sub_context: SenderSubscription | None = None
        self._deadline_timer: Any = None
        self._ready_timer: Any = None
        self._armed = False  # this configuration's steps are subscribed (or will be)
        self.counts = dict.fromkeys(
            ('actions', 'fresh', 'stale', 'safe', 'rejected', 'mismatched', 'foreign'), 0)
        self._foreign_before = 0  # refused by the pairings of earlier configurations
        self._forget_steps()
        self._rate = RateMeter()
        self._latency = LatencyMeter()  # observation in -> action out
        self._window = WindowCounts()
        self._clock_watch = ClockWatch(self)
        self._pub: Any = None
        self._pub_diag = self.create_publisher(DiagnosticArray, TOPICS.DIAGNOSTICS, 10)
        self._wait_report = WaitReport(self)
        # autostart: configure (the checkpoint first: a bad one is the process's one line) and
        # activate now, as an unmanaged node would start.
        self.autostart(self.params['autostart'])
        handshake_of(self).sha256 = lambda: '' if self.loaded is None else self.loaded.sha256
        steady_timer(self, 1.0, self._publish_diagnostics)
        handshake_of(self).urgent = self._publish_diagnostics  # a refused hello: ERROR at once
        self._live = serve_live_changes(self, SPECS, self.params, self._apply_live,
                                        check=self._check_live, prepare=self._prepare_live)
        serve_switch(self, 'freeze_context', self._freeze_context)
        serve_swap(self, 'stage_checkpoint', self._stage_checkpoint)

    # -- lifecycle (lifecycle.py) ------------------------------------------------------------
    def _configure(self) -> None:
        """Load the checkpoint (or the task, for the random policy); subscribe to the inputs."""
        if self.params['checkpoint']:
            self.loaded = load_inference_agent('policy', self.params)
            self.agent = self.loaded.agent
            low, high = self.agent.action_low, self.agent.action_high
            obs_kind, obs_shape = self.agent.obs_kind, self.agent.obs_shape
            self.needs_context = self.agent.context_dim > 0
        else:
            if not self.params['task']:
                raise ValueError('policy: give a checkpoint (-p checkpoint:=PATH), or a task '
                                 '(-p task:=Cheetah-Run-v0) for the random policy')
            from sim_bridge.registry import make_task

            task = make_task(self.params['task'])
            low, high = task.action_bounds
            obs_kind, obs_shape = 'state', (task.state_dim,)
            task.close()
            self.needs_context = False
        self.frozen = self._parse_frozen(self.params['frozen_context'])
        self.low = np.asarray(low, dtype=np.float32)
        self.high = np.asarray(high, dtype=np.float32)
        self.decoder = ObservationDecoder(obs_kind, obs_shape, self.params['image_size'])
        self._forget_steps()
        # Steps and observations from one step source only (paired by GID and name, as the
        # contexts below): another publisher on them is refused, counted and an ERROR.
        self.inputs = StepInputs(self, self.decoder, self._on_observation, self._reject,
                                 mode=self.params['mode'],
                                 subscribe=not self.params['expected_subscribers'],
                                 source=self.params['step_source'])
        self.assembler = self.inputs.assembler
        # Contexts come from one estimator only (the only publisher, by GID; followed through
        # the handshake when it restarts): another publisher is refused, counted and an ERROR.
        self._senders = SenderPairing(self, self.resolve_topic_name(TOPICS.CONTEXT),
                                      self.params['context_source'], what='contexts',
                                      setting='context_source')
        self._sub_context = SenderSubscription(
            self, ContextEstimate, TOPICS.CONTEXT, step_qos(depth=100), self._on_context,
            admit=self._senders.accepts) if self.needs_context else None
        # Armed only while an observation waits for its context (no polling): it fires once,
        # when context k is overdue by context_deadline.
        self._deadline_timer = steady_timer(self, self.params['context_deadline'],
                                            self._check_deadline)
        self._deadline_timer.cancel()
        source = 'random policy' if self.loaded is None else \
            f'{self.loaded.agent.method} checkpoint for {self.loaded.agent.task}: loaded ' \
            f'{self.loaded.describe()}'
        if self.frozen is not None:
            source += ', context FROZEN (frozen_context)'
        lag = self.params['context_lag']
        uses = f'acts on context k - {lag} (context_lag)' if lag else 'waits for context k'
        self.get_logger().info(f'{source}; {obs_kind} observations, '
                               f'{uses if self.needs_context else "no context"}')

    def _activate(self) -> None:
        """Act from the next observation on, as if just started (no context carried over).

        The action publisher appears only once a context source exists: sim_bridge starts
        stepping when it sees an action publisher, so step 0 already gets its context.
        Steady clocks: with use_sim_time, ROS time only moves once sim_bridge steps.
        """
        self._forget_steps()
        if not self._armed and self._ready_timer is None:
            self._ready_timer = steady_timer(self, 0.05, self._become_ready)

    def _deactivate(self) -> None:
        """The observation waiting for its context gets the safe action; then none get any."""
        self._stop_ready_timer()
        if self._waiting is not None:
            step, _wanted, feedback, _obs, _deadline = self._waiting
            self._waiting = None
            self._deadline_timer.cancel()
            self._publish(step, feedback, self._safe_action(), 'safe')

    def _release(self) -> None:
        """Unsubscribe, drop the timers and the checkpoint (the action publisher stays)."""
        self._stop_ready_timer()
        self._foreign_before += sum(pairing.refused for pairing in (self._senders, self.inputs)
                                    if pairing is not None)
        if self._sub_context is not None:
            self._sub_context.destroy()
        if self.inputs is not None:
            self.inputs.destroy()
        if self._senders is not None:
            unwatch_peers(self, [self._senders])
        if self._deadline_timer is not None:
            self.destroy_timer(self._deadline_timer)
        self.inputs = self._senders = self._sub_context = self._deadline_timer = None
        self.agent = self.loaded = self._pending = self._staged = None
        self._adopting, self._armed, self.frozen = '', False, None
        self._forget_steps()

    def _stop_ready_timer(self) -> None:
        if self._ready_timer is not None:
            self._ready_timer.cancel()
            self.destroy_timer(self._ready_timer)
            self._ready_timer = None

    def _forget_steps(self) -> None:
        """No observation waiting, no context kept: the state of a node just started."""
        self._contexts: dict[int, np.ndarray] = {}
        self._newest_context: tuple[float, np.ndarray] | None = None
        # (observation step, context step it waits for, feedback, observation, deadline)
        self._waiting: tuple[int, int, Any, np.ndarray, float] | None = None
        self._episode_start = 0  # step of the current episode's first observation
        self._first_context: int | None = None  # first context's step since start / redeploy
        self._received: tuple[int, float] | None = None  # the newest observation's step, time
        self._first_step_at: float | None = None  # "no context for N s" counts from here

    def _parse_frozen(self, text: str, agent: InferenceAgent | None = None
                      ) -> np.ndarray | None:
        """The frozen_context parameter as a vector of the agent's context size, or None."""
        if not text.strip():
            return None
        agent = agent or self.agent
        size = 0 if agent is None else agent.context_dim
        try:
            values = np.asarray([float(v) for v in text.split(',')], dtype=np.float32)
        except ValueError:
            raise ValueError(f'policy: parameter frozen_context={text!r} must be '
                             'comma-separated numbers') from None
        if values.shape != (size,) or not np.isfinite(values).all():
            raise ValueError(f'policy: parameter frozen_context needs {size} finite values '
                             f"(the checkpoint's context size), got {text!r}")
        return values

    def _check_live(self, values: dict[str, Any]) -> None:
        """frozen_context must fit the checkpoint (unconfigured: configure checks it)."""
        if self.configured:
            self._parse_frozen(values['frozen_context'])

    def _prepare_live(self, changed: dict[str, Any]) -> None:
        """Load a new checkpoint (even the same path: the file may be new) or refuse it.

        Unconfigured, a change is taken as it is: the next configure loads it.
        """
        self._pending = None
        if not self.configured or 'checkpoint' not in changed or \
                changed['checkpoint'] == self._adopting:
            return
        if self.agent is None or not changed['checkpoint']:
            raise ValueError('policy: switching between the random policy and a checkpoint '
                             'needs a restart')
        loaded = load_inference_agent('policy', {**self.params, **changed})
        check_swappable('policy', self.agent, loaded.agent)
        if (loaded.agent.context_dim > 0) != self.needs_context:
            raise ValueError('policy: the new checkpoint changes whether a context is used; '
                             'restart the node to load it')
        self._parse_frozen(changed.get('frozen_context', self.params['frozen_context']),
                           loaded.agent)
        self._pending = loaded

    def _apply_live(self, changed: dict[str, Any]) -> None:
        """Live parameter changes read through self.params; frozen_context needs parsing."""
        if not self.configured:
            return
        if 'checkpoint' in changed and self._pending is not None:
            self.loaded, self._pending = self._pending, None
            self.agent = self.loaded.agent
            self._contexts.clear()  # estimates of the old pair: never acted on again
            self._newest_context = None
            self._first_context = None
            self.get_logger().info(f'redeployed live: {self.agent.method} checkpoint '
                                   f'{self.loaded.describe()}')
        if 'checkpoint' in changed and changed['checkpoint'] != self._adopting:
            self._staged = None  # a redeploy by parameter overrides a staged swap
        if 'frozen_context' in changed or 'checkpoint' in changed:
            self.frozen = self._parse_frozen(self.params['frozen_context'])

    # -- operator services (services.py) ----------------------------------------------------
    def _freeze_context(self, freeze: bool) -> str:
        """Freeze psi at the train mean (else the newest estimate), or make it live."""
        self._require_configured()
        if not freeze:
            text, done = '', 'psi live again (frozen_context cleared)'
        else:
            if self.agent is None or not self.needs_context:
                raise ValueError('this policy uses no context: nothing to freeze')
            mean = self.agent.extra.get(TRAIN_MEAN_KEY)
            if mean is not None:
                values, source = np.asarray(mean, np.float32), "the checkpoint's train mean"
            elif self._newest_context is not None:
                values, source = self._newest_context[1], 'the newest estimate'
            else:
                raise ValueError('no context to freeze at yet (no estimate, no train mean in '
                                 'the checkpoint)')
            text = ','.join(f'{v:.9g}' for v in values)
            done = f'psi frozen at {source} ({text}): frozen_context set'
        result = self.set_parameters([Parameter('frozen_context', value=text)])[0]
        if not result.successful:
            raise ValueError(result.reason)
        return done

    def _stage_checkpoint(self, checkpoint: str, expect_sha256: str) -> tuple[str, str]:
        """Load a checkpoint to switch to at its first estimate ('' unstages); ValueError."""
        self._require_configured()
        if not checkpoint:
            self._staged = None
            return 'nothing staged', '' if self.loaded is None else self.loaded.sha256
        if self.loaded is None:
            raise ValueError('the random policy cannot switch to a checkpoint: restart it')
        self._prepare_live({'checkpoint': checkpoint})  # loads and checks it, or refuses
        staged, self._pending = self._pending, None
        assert staged is not None
        if expect_sha256 and staged.sha256 != expect_sha256:
            raise ValueError(f'{staged.path} has sha256 {staged.sha256[:12]}, expected '
                             f'{expect_sha256[:12]}')
        self._staged = staged
        return (f'staged {staged.describe()}: used from the first estimate stamped with it',
                staged.sha256)

    def _require_configured(self) -> None:
        """An operator service of an unconfigured node is refused with the way out."""
        if not self.configured:
            raise ValueError(f'unconfigured: `ros2 lifecycle set '
                             f'{self.get_fully_qualified_name()} configure` first')

    def _adopt_staged(self) -> None:
        """The estimator runs the staged checkpoint now: so does the policy, from this step."""
        assert self._staged is not None
        self._pending, self._staged = self._staged, None
        path = str(self._pending.path)
        self._apply_live({'checkpoint': path})
        self._adopting = path  # `checkpoint` tells what runs, without loading it again
        result = self.set_parameters([Parameter('checkpoint', value=path)])[0]
        self._adopting = ''
        if not result.successful:
            self.get_logger().warning(f'runs {path}, parameter checkpoint not updated: '
                                      f'{result.reason}')

    def _become_ready(self) -> None:
        """First activation: the action publisher once a context source exists; the steps."""
        if self._pub is None and self.needs_context and \
                count_publishers(self, TOPICS.CONTEXT) == 0:
            self._wait_report.waiting('a context_estimator publishing on '
                                      f'{self.resolve_topic_name(TOPICS.CONTEXT)}')
            return
        if self._pub is None:  # kept for the node's life: the pairings of its readers hold
            self._pub = self.create_publisher(Action, TOPICS.ACTION,
                                              action_qos(self.params['mode']))
        self._stop_ready_timer()
        self._armed = True
        assert self.inputs is not None
        # With expected_subscribers: observations only once sim_bridge and the recorder hear
        # the actions and this node hears the estimator (sim_bridge then waits for this node
        # as one of its step subscribers), so step 0 gets its context here.
        readers = [(self._sub_context, 1)] if self._sub_context is not None else []
        self.inputs.subscribe_when_heard(self._pub, self.params['expected_subscribers'],
                                         self.params['subscriber_timeout'], readers)

    # -- inputs ------------------------------------------------------------------------------
    def _on_context(self, msg: ContextEstimate) -> None:
        if self._staged is not None and msg.checkpoint_sha256 == self._staged.sha256:
            self._adopt_staged()
        if self.loaded is not None and msg.checkpoint_sha256 != self.loaded.sha256:
            self.counts['mismatched'] += 1
            self.get_logger().warning(
                f'context {msg.step} comes from checkpoint sha256 '
                f'{msg.checkpoint_sha256[:12] or "(none)"}, the policy runs '
                f'{self.loaded.sha256[:12]}: not acting on it (redeploy both)',
                throttle_duration_sec=2.0)
            return
        context = np.asarray(msg.data, dtype=np.float32)
        if self.agent is not None and context.shape != (self.agent.context_dim,):
            self._reject(msg.step, TOPICS.CONTEXT, ValueError(
                f'context has {context.size} values, expected {self.agent.context_dim}'))
            return
        self._newest_context = (time.monotonic(), context)
        self._contexts[msg.step] = context
        if self._first_context is None:
            self._first_context = msg.step
        for old in [step for step in self._contexts if step < msg.step - MAX_CONTEXT_LAG]:
            del self._contexts[old]
        if self._waiting is not None and self._waiting[1] == msg.step:
            step, _wanted, feedback, obs, _deadline = self._waiting
            self._waiting = None
            self._deadline_timer.cancel()
            self._act(step, feedback, obs, context, 'fresh')

    def _reject(self, step: int, topic: str, error: ValueError) -> None:
        self.counts['rejected'] += 1
        self.get_logger().warning(f'rejected {topic} for step {step}: {error}',
                                  throttle_duration_sec=2.0)

    # -- acting ------------------------------------------------------------------------------
    def _on_observation(self, parts: StepParts) -> None:
        if not self.active:  # inactive: sim_bridge applies its safe action after its timeout
            return
        feedback: StepFeedback = parts.parts['feedback']
        obs = self.decoder.observation(parts.parts['obs'][1], feedback.first)
        if self._waiting is not None:  # a newer observation overtook the one still waiting
            self._expire_waiting()
        if feedback.first:
            self._episode_start = parts.step
        self._received = (parts.step, parts.parts['obs'][0])
        if self._first_step_at is None:
            self._first_step_at = self._received[1]
        wanted = self._wanted_context(parts.step)
        if not self.needs_context:
            self._act(parts.step, feedback, obs, np.zeros(0, np.float32), 'fresh')
        elif wanted in self._contexts:
            self._act(parts.step, feedback, obs, self._contexts[wanted], 'fresh')
        else:
            deadline = time.monotonic() + self.params['context_deadline']
            self._waiting = (parts.step, wanted, feedback, obs, deadline)
            # Deadline first, then the timer: it cannot fire before the deadline.
            self._deadline_timer.timer_period_ns = int(self.params['context_deadline'] * 1e9)
            self._deadline_timer.reset()
            if self.agent is not None:  # phi(o_k) while the estimator computes psi_k
                self.agent.encode_ahead(obs)

    def _wanted_context(self, step: int) -> int:
        """The context step that observation `step` is acted on with: step - context_lag.

        Never one from before this episode's first step, nor from before the first context
        received since start or redeploy: those never come (with none yet, context `step`).
        """
        floor = step if self._first_context is None else min(self._first_context, step)
        return max(step - self.params['context_lag'], self._episode_start, floor)

    def _check_deadline(self) -> None:
        if self._waiting is not None and time.monotonic() >= self._waiting[4]:
            self._expire_waiting()

    def _expire_waiting(self) -> None:
        """Context k did not come in time: act on the newest one, or safely if none is recent."""
        assert self._waiting is not None
        step, _wanted, feedback, obs, _deadline = self._waiting
        self._waiting = None
        self._deadline_timer.cancel()
        newest = self._newest_context
        # From the last context, or from the first step: not from node start (a node that
        # waited a minute for its peers has not been without a context for a minute).
        first = self._first_step_at if self._first_step_at is not None else time.monotonic()
        last_seen = first if newest is None else newest[0]
        if newest is None or time.monotonic() - last_seen > self.params['context_timeout']:
            self._publish(step, feedback, self._safe_action(), 'safe')
            self.get_logger().warning(
                f'no context for {time.monotonic() - last_seen:.1f} s: safe action for step '
                f'{step}', throttle_duration_sec=2.0)
        else:
            self._act(step, feedback, obs, newest[1], 'stale')
            self.get_logger().warning(f'context {step} late: acting on the newest context',
                                      throttle_duration_sec=2.0)

    def _safe_action(self) -> np.ndarray:
        return np.clip(np.zeros_like(self.low), self.low, self.high)

    def _act(self, step: int, feedback: StepFeedback, obs: np.ndarray, context: np.ndarray,
             kind: str) -> None:
        if self.agent is None:
            action = self.rng.uniform(self.low, self.high).astype(np.float32)
        else:
            if self.frozen is not None:
                context = self.frozen
            action = self.agent.act(obs, context, deterministic=self.params['deterministic'],
                                    noise=self.params['noise'], rng=self.rng)
        self._publish(step, feedback, action, kind)

    def _publish(self, step: int, feedback: StepFeedback, action: np.ndarray, kind: str) -> None:
        if self._pub is None:
            return
        msg = Action()
        msg.header.stamp = feedback.header.stamp
        msg.header.frame_id = feedback.header.frame_id
        msg.step = step
        msg.data = np.clip(action, self.low, self.high).astype(np.float32).tolist()
        self._pub.publish(msg)
        self.counts['actions'] += 1
        self.counts[kind] += 1
        self._rate.tick()
        if self._received is not None and self._received[0] == step:
            self._latency.add(time.monotonic() - self._received[1])
            self._received = None

    def _publish_diagnostics(self) -> None:
        refused = [p.refused for p in (self._senders, self.inputs) if p is not None]
        self.counts['foreign'] = self._foreign_before + sum(refused)
        (p50, p99), _ = self._latency.report()
        values = {'rate_hz': f'{self._rate.rate:.1f}',
                  'dropped': 0 if self.inputs is None else self.inputs.assembler.dropped,
                  'context_lag': self.params['context_lag'], 'latency_p50_ms': f'{p50:.2f}',
                  'latency_p99_ms': f'{p99:.2f}', **self.counts, **self._live.values(),
                  'lifecycle': self.lifecycle_state()}
        grown = self._window.delta(self.counts)
        problems = [*self._window.problems(grown, WARN_COUNTS), *self._live.problems()]
        if not self.active:
            problems.append(f'{values["lifecycle"]}: not acting (`ros2 lifecycle set '
                            f'{self.get_fully_qualified_name()} activate`)')
        _, stalled = rate_problems(self._rate.rate, grown['actions'], 0.0, 0.0,
                                   self.active and self.counts['actions'] > 0, what='actions')
        slow, late = latency_problems(p99, self.params['latency_warn_ms'],
                                      self.params['latency_error_ms'], 'observation -> action')
        errors = [*(self._senders.errors() if self._senders and self.needs_context else []),
                  *(self.inputs.errors() if self.inputs else []), *self._clock_watch.errors(),
                  *stalled, *late]
        self._pub_diag.publish(diagnostics_message(self, 'actions', values, [*problems, *slow],
                                                   errors))

    def destroy_node(self) -> None:
        """The step and context subscriptions are ours (not rclpy's): they go before the node."""
        self._release()
        super().destroy_node()

def main(args: list[str] | None = None) -> int:
    """Entry point of `ros2 run zeus_ros policy_node`."""
    return run_node(PolicyNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
