"""context_estimator node: psi(H_k) from the last k transitions of the running episode.

For step k it needs o_k and StepFeedback k (reward r_k, applied a_{k-1}, episode start); it
appends (o_{k-1}, a_{k-1}, r_k, o_k) to the history, or clears it at an episode start, and
publishes ContextEstimate k with the stamp of observation k. A step that never arrives is a
counted gap (the transition across it is not formed), never a silent misalignment. When the
checkpoint holds a context read-out (learning/readout.py), the same step's estimate in
the context's units goes out on zeus/context_readout (ContextTruth type: names and values); with a
novelty monitor, zeus/context_novelty carries its score, threshold and flag per step, and
/diagnostics warns while most steps lie outside the training contexts.
"""

from __future__ import annotations

import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from zeus_msgs.msg import ContextEstimate, ContextTruth, StepFeedback

from zeus_ros.learning.readout import NoveltyTracker
from zeus_ros.nodes.agent_loader import LoadedAgent, check_swappable, load_inference_agent
from zeus_ros.nodes.assembler import StepParts
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
from zeus_ros.nodes.peers import steady_timer
from zeus_ros.nodes.spin import run_node
from zeus_ros.nodes.topics import TOPICS, publisher_qos, step_qos

SPECS: dict[str, Spec] = {
    'checkpoint': Spec('', 'checkpoint holding phi and psi; a live change loads it (same task, '
                       'observations and actions) and stamps the estimates with its sha256',
                       live=True, required=True),
    'task': Spec('', 'task the checkpoint must be for (empty: any)'),
    'mode': Spec('lockstep', "sim_bridge's mode (sets the image QoS)",
                 choices=('lockstep', 'realtime')),
    'image_size': Spec(84, 'frame height and width in pixels', low=1, high=1024),
    'device': Spec('cpu', 'torch device'),
    'torch_threads': Spec(1, 'torch intra-op threads', low=1),
    **HEARD_SPECS,
    **latency_specs(20.0, 200.0, 'observation -> context'),
    **LOCK_SPECS,
    **LIFECYCLE_SPECS,
}
WARN_COUNTS = ('gaps', 'rejected', 'foreign')
"""Counted faults that WARN while they grow (health.WINDOW_S), then clear."""


class ContextEstimatorNode(ManagedNode):
    """Keeps the rolling history and publishes the learned context for every step.

    Managed (lifecycle.py): configure loads the checkpoint and subscribes to the steps;
    activate publishes contexts (the publisher appears at the first activation and stays for
    the node's life, so the policy's pairing holds); deactivate stops estimating and
    publishing (a step missed meanwhile is a counted gap of the history).
    """

    def __init__(self, **node_options: Any) -> None:
        """`node_options` go to rclpy's Node (cli_args, context): one process can hold several."""
        super().__init__('context_estimator', **node_options)
        self.params = declare_specs(self, SPECS)
        self.loaded: LoadedAgent | None = None
        self._pending: LoadedAgent | None = None
        self.agent: Any = None
        self.inputs: StepInputs | None = None
        self._readers: list[tuple[Any, int]] = []  # must hear their publisher before the steps
        self._armed = False  # this configuration's steps are subscribed (or will be)
        self.counts = dict.fromkeys(('estimates', 'gaps', 'missing_steps', 'rejected',
                                     'foreign'), 0)
        self._foreign_before = 0  # refused by the step pairings of earlier configurations
        self._prev: tuple[int, np.ndarray] | None = None
        self._missing_in_episode = 0
        self._rate = RateMeter()
        self._latency = LatencyMeter()  # observation in -> context out
        self._pub_diag = self.create_publisher(DiagnosticArray, TOPICS.DIAGNOSTICS, 10)
        self._window = WindowCounts()
        self._clock_watch = ClockWatch(self)
        self._pub: Any = None
        # The estimate in the context's units, for people and plotting tools (the policy never
        # reads it): published whenever the checkpoint holds a read-out; the publisher exists
        # only then, so a viewer can tell "no read-out" from "not arrived yet".
        self._pub_readout: Any = None
        self._pub_novelty: Any = None
        self._novelty: NoveltyTracker | None = None
        self._novel_steps = [0, 0]  # steps scored above / at or below the threshold, per second
        self._last_novelty = float('nan')
        # autostart: configure (the checkpoint first: a bad one is the process's one line) and
        # activate now, as an unmanaged node would start.
        self.autostart(self.params['autostart'])
        # the start hello's checkpoint
        handshake_of(self).sha256 = lambda: '' if self.loaded is None else self.loaded.sha256
        steady_timer(self, 1.0, self._publish_diagnostics)
        handshake_of(self).urgent = self._publish_status  # a refused hello: ERROR at once
        self._live = serve_live_changes(self, SPECS, self.params, self._apply_live,
                                        prepare=self._prepare_live)

    # -- lifecycle (lifecycle.py) ------------------------------------------------------------
    def _configure(self) -> None:
        """Load the checkpoint; subscribe to the steps (and true contexts) of one source."""
        self.loaded = load_inference_agent('context_estimator', self.params)
        self.agent = self.loaded.agent
        self.history = self.agent.new_history()
        self.decoder = ObservationDecoder(self.agent.obs_kind, self.agent.obs_shape,
                                          self.params['image_size'])
        self._prev, self._missing_in_episode = None, 0
        # Steps, observations (and true contexts) from one step source only: paired by GID.
        self.inputs = StepInputs(
            self, self.decoder, self._on_step, self._reject, mode=self.params['mode'],
            extra_parts=['truth'] if self.agent.needs_true_context else [],
            subscribe=not self.params['expected_subscribers'],
            source=self.params['step_source'])
        self.assembler = self.inputs.assembler
        self._readers = []
        if self.agent.needs_true_context:
            self._readers.append((self.inputs.subscription(
                ContextTruth, TOPICS.CONTEXT_TRUTH,
                lambda m: self.assembler.add(m.step, 'truth', m), step_qos(), 'true contexts'),
                1))
        self.get_logger().info(
            f'{self.agent.method} checkpoint for {self.agent.task} ({self.agent.obs_kind}, '
            f'k={self.agent.k}, context dim {self.agent.context_dim}): loaded '
            f'{self.loaded.describe()}')
        self._log_readout()

    def _activate(self) -> None:
        """The context publisher (first activation), then the steps once it is heard."""
        # Publisher after the subscriptions: a peer that sees it knows they already exist;
        # with expected_subscribers the steps are subscribed once the readers hear the context.
        if self._pub is None:  # kept for the node's life: the policy's pairing holds
            self._pub = self.create_publisher(ContextEstimate, TOPICS.CONTEXT,
                                              publisher_qos(self.params['mode']))
        expected = self.params['expected_subscribers']
        if not self._armed and expected and self.inputs is not None:
            self.inputs.subscribe_when_heard(self._pub, expected,
                                             self.params['subscriber_timeout'], self._readers)
        self._armed = True

    def _release(self) -> None:
        """Unsubscribe and drop the checkpoint (the publishers stay, unused till configured)."""
        if self.inputs is not None:
            self._foreign_before += self.inputs.refused
            self.inputs.destroy()
        self.inputs, self._readers, self._armed = None, [], False
        self.loaded = self._pending = self.agent = self._novelty = None
        self._prev = None

    def _log_readout(self) -> None:
        novelty = self.loaded.novelty
        self._novelty = None if novelty is None else NoveltyTracker(novelty, self.agent.k)
        if novelty is not None:
            if self._pub_novelty is None:
                self._pub_novelty = self.create_publisher(
                    ContextTruth, TOPICS.CONTEXT_NOVELTY, publisher_qos(self.params['mode']))
            self.get_logger().info(f'{self._pub_novelty.topic_name}: {novelty.describe()}')
        if self.loaded.readout is None:
            self.get_logger().info(f'no context read-out in the checkpoint: nothing on '
                                   f'{TOPICS.CONTEXT_READOUT} (zeus export calibrates one)')
            return
        if self._pub_readout is None:
            self._pub_readout = self.create_publisher(
                ContextTruth, TOPICS.CONTEXT_READOUT, publisher_qos(self.params['mode']))
        self.get_logger().info(f'{self._pub_readout.topic_name}: '
                               f'{self.loaded.readout.describe()}')

    def _prepare_live(self, changed: dict[str, Any]) -> None:
        """Load a new checkpoint (even the same path: the file may be new) or refuse it."""
        self._pending = None
        if self.configured and 'checkpoint' in changed:  # unconfigured: configure loads it
            loaded = load_inference_agent('context_estimator', {**self.params, **changed})
            check_swappable('context_estimator', self.agent, loaded.agent)
            self._pending = loaded

    def _apply_live(self, changed: dict[str, Any]) -> None:
        """Swap in the checkpoint loaded by the check; the episode's history carries over."""
        if 'checkpoint' not in changed or self._pending is None or not self.configured:
            return
        self.loaded, self._pending = self._pending, None
        self.agent = self.loaded.agent
        old = self.history.arrays()
        self.history = self.agent.new_history()
        for slot in range(old.hist_mask.shape[0]):
            if old.hist_mask[slot]:
                self.history.push(old.hist_obs[slot], old.hist_action[slot],
                                  float(old.hist_reward[slot, 0]), old.hist_next_obs[slot])
        self.get_logger().info(f'redeployed live: {self.agent.method} checkpoint '
                               f'{self.loaded.describe()}')
        self._log_readout()

    def _reject(self, step: int, topic: str, error: ValueError) -> None:
        self.counts['rejected'] += 1
        self.get_logger().warning(f'rejected {topic} for step {step}: {error}',
                                  throttle_duration_sec=2.0)

    def _on_step(self, parts: StepParts) -> None:
        if not self.active:  # inactive: no estimate (the steps missed are a gap on activate)
            return
        feedback: StepFeedback = parts.parts['feedback']
        received, raw = parts.parts['obs']
        step = parts.step
        obs = self.decoder.observation(raw, feedback.first)
        if feedback.first:
            self.history.clear()
            self._missing_in_episode = 0
        elif self._prev is not None and self._prev[0] == step - 1 and \
                len(feedback.applied_action) == self.agent.action_dim:
            self.history.push(self._prev[1], np.asarray(feedback.applied_action, np.float32),
                              feedback.reward, obs)
        else:
            missing = step - self._prev[0] - 1 if self._prev is not None else 1
            self.counts['gaps'] += 1
            self.counts['missing_steps'] += max(missing, 1)
            self._missing_in_episode += max(missing, 1)
            self.get_logger().warning(
                f'gap before step {step}: {max(missing, 1)} step(s) missing; the transition '
                'across it is left out of the history', throttle_duration_sec=2.0)
        self._prev = (step, obs)
        truth = parts.parts.get('truth')
        context = self.agent.context(self.history, None if truth is None else truth.values)
        msg = ContextEstimate()
        msg.header.stamp = feedback.header.stamp
        msg.step = step
        msg.data = context.astype(np.float32).tolist()
        msg.history_length = len(self.history)
        msg.missing_steps = self._missing_in_episode
        msg.checkpoint_sha256 = self.loaded.sha256
        self._pub.publish(msg)
        if self.loaded.readout is not None and self._pub_readout is not None:
            readout = ContextTruth()
            readout.header.stamp = feedback.header.stamp
            readout.step = step
            readout.names = list(self.loaded.readout.names)
            readout.values = self.loaded.readout.apply(context).tolist()
            self._pub_readout.publish(readout)
        if self._novelty is not None and self._pub_novelty is not None:
            self._publish_novelty(feedback, self._novelty.update(context, len(self.history),
                                                                 feedback.first))
        self.counts['estimates'] += 1
        self._rate.tick()
        self._latency.add(time.monotonic() - received)

    def _publish_novelty(self, feedback: StepFeedback, score: float | None) -> None:
        """Publish the step's novelty (none before the history holds k transitions)."""
        if score is None or self._novelty is None:
            return
        threshold = self._novelty.monitor.threshold
        novel = score > threshold
        self._novel_steps[0 if novel else 1] += 1
        msg = ContextTruth()
        msg.header.stamp = feedback.header.stamp
        msg.step = feedback.step
        msg.names = ['novelty', 'threshold', 'novel']
        msg.values = [score, threshold, float(novel)]
        self._pub_novelty.publish(msg)
        self._last_novelty = score

    def _publish_diagnostics(self) -> None:
        self._publish_status()
        self._publish_novelty_status()

    def _publish_status(self) -> None:
        """The node's own status ('context'): also published at once for a refused hello."""
        (p50, p99), _ = self._latency.report()
        inputs = self.inputs
        self.counts['foreign'] = self._foreign_before + (0 if inputs is None else inputs.refused)
        values = {'rate_hz': f'{self._rate.rate:.1f}', 'latency_p50_ms': f'{p50:.2f}',
                  'latency_p99_ms': f'{p99:.2f}',
                  'dropped': 0 if inputs is None else inputs.assembler.dropped,
                  'late': 0 if inputs is None else inputs.assembler.late, **self.counts,
                  **self._live.values(), 'lifecycle': self.lifecycle_state()}
        grown = self._window.delta(self.counts)
        problems = [*self._window.problems(grown, WARN_COUNTS), *self._live.problems()]
        if not self.active:
            problems.append(f'{values["lifecycle"]}: no estimates (`ros2 lifecycle set '
                            f'{self.get_fully_qualified_name()} activate`)')
        _, stalled = rate_problems(self._rate.rate, grown['estimates'], 0.0, 0.0,
                                   self.active and self.counts['estimates'] > 0,
                                   what='estimates')
        slow, late = latency_problems(p99, self.params['latency_warn_ms'],
                                      self.params['latency_error_ms'], 'observation -> context')
        errors = [*(inputs.errors() if inputs is not None else []), *self._clock_watch.errors(),
                  *stalled, *late]
        self._pub_diag.publish(diagnostics_message(self, 'context', values, [*problems, *slow],
                                                   errors))

    def _publish_novelty_status(self) -> None:
        """The 'context novelty' status, over the steps of the last 1-s tick."""
        if self._novelty is not None:
            # WARN while most steps of the last second lay outside the training contexts.
            novel, usual = self._novel_steps
            self._novel_steps = [0, 0]
            threshold = self._novelty.monitor.threshold
            last = self._last_novelty
            warn = [f'context novel: {novel} of {novel + usual} steps above the novelty '
                    f'threshold {threshold:.3g} (latest {last:.3g}): a context it was not '
                    'trained on'] if novel > usual else []
            self._pub_diag.publish(diagnostics_message(
                self, 'context novelty', {'novelty': f'{last:.3f}',
                                          'threshold': f'{threshold:.3f}',
                                          'novel_steps': novel, 'steps': novel + usual}, warn,
                peers=False))


    def destroy_node(self) -> None:
        """The step subscriptions are ours (not rclpy's): they go before the node."""
        self._release()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point of `ros2 run zeus_ros context_estimator_node`."""
    return run_node(ContextEstimatorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
