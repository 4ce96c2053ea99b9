"""Turn observation messages into the arrays a checkpoint expects (state vector or frame stack)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
import time
from typing import TYPE_CHECKING, Any

import numpy as np
from sensor_msgs.msg import Image
from zeus_msgs.msg import StateVector, StepFeedback

from zeus_ros.learning.frames import FrameStack
from zeus_ros.nodes.assembler import StampJoin, StepAssembler, StepParts
from zeus_ros.nodes.diagnostics import unwatch_peers
from zeus_ros.nodes.messages import array_from_image, stamp_ns
from zeus_ros.nodes.params import Spec
from zeus_ros.nodes.peers import call_when_ready, unmatched_readers
from zeus_ros.nodes.senders import SenderPairing, SenderSubscription
from zeus_ros.nodes.topics import TOPICS, image_qos, step_qos

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ['HEARD_SPECS', 'ObservationDecoder', 'StepInputs']

HEARD_SPECS: dict[str, Spec] = {
    'expected_subscribers': Spec(0, "subscribe to the steps only once this node's output has "
                                 'matched this many subscribers (launchers set it: readers + '
                                 'recorder), so none misses step 0; 0: do not wait', low=0),
    'step_source': Spec('', 'node whose steps and observations are used, e.g. /r1/sim_bridge '
                        '(empty: the only publisher of zeus/step when the first step arrives); '
                        'any other publisher is refused and an ERROR (docs/security.md)'),
    'subscriber_timeout': Spec(20.0, 'seconds to wait for expected_subscribers (and for the '
                               'step source and the inputs to match); then log what is still '
                               'short and subscribe anyway', low=0.0),
}
"""Start-up parameters of the nodes whose output answers a step (context_estimator, policy)."""


class ObservationDecoder:
    """Decodes o_k per step; keeps the frame stack of the running episode for pixel agents."""

    def __init__(self, obs_kind: str, obs_shape: tuple[int, ...], image_size: int = 84) -> None:
        self.obs_kind = obs_kind
        self.obs_shape = tuple(obs_shape)
        self.image_size = image_size
        self.frames = FrameStack(num_frames=obs_shape[0] // 3, size=image_size) \
            if obs_kind == 'pixels' else None

    def validate(self, msg: StateVector | Image) -> np.ndarray:
        """Check one message and return its raw array; ValueError says what is wrong."""
        if self.obs_kind == 'pixels':
            return array_from_image(msg, (self.image_size, self.image_size))
        data = np.asarray(msg.data, dtype=np.float32)
        if data.shape != self.obs_shape:
            raise ValueError(f'state vector has {data.size} values, the checkpoint expects '
                             f'{self.obs_shape[0]}')
        if not np.all(np.isfinite(data)):
            raise ValueError('state vector holds NaN or Inf')
        return data

    def observation(self, raw: np.ndarray, first: bool) -> np.ndarray:
        """The agent's observation for this step (a new frame stack at an episode start)."""
        if self.frames is None:
            return raw
        return self.frames.reset(raw) if first else self.frames.push(raw)


class StepInputs:
    """Subscribes a node to StepFeedback and its observation topic; assembles them per step.

    Both come from one step source only, paired by publisher GID and node name (`source`, the
    `step_source` parameter, or the only publisher of the steps; senders.py): messages of any
    other publisher are refused unread and counted (`refused`), and `errors()` names it.

    `on_step` receives StepParts with 'feedback' (the StepFeedback) and 'obs' (receipt time,
    validated raw array), plus any `extra_parts` the node adds itself through `assembler.add`.
    A message that fails validation goes to `on_reject(step, topic, error)` and is dropped.
    With `subscribe=False` the subscriptions wait for `subscribe()` or `subscribe_when_heard()`.
    """

    def __init__(self, node: Node, decoder: ObservationDecoder,
                 on_step: Callable[[StepParts], None],
                 on_reject: Callable[[int, str, ValueError], None], *, mode: str,
                 extra_parts: Sequence[str] = (), subscribe: bool = True,
                 source: str = '') -> None:
        self.node = node
        self.decoder = decoder
        self.on_reject = on_reject
        self.mode = mode
        self.assembler = StepAssembler(['feedback', 'obs', *extra_parts], on_step)
        self._join = StampJoin(lambda step, value: self.assembler.add(step, 'obs', value))
        self.subscribed = False
        self.pairings: list[SenderPairing] = []
        self._subscriptions: list[SenderSubscription] = []
        self._source = source
        self._steps = self.pairing(TOPICS.STEP, 'steps')
        if subscribe:
            self.subscribe()

    def pairing(self, topic: str, what: str) -> SenderPairing:
        """A pairing on `topic` with the step source (unnamed: the steps' pairing decides)."""
        first = self.pairings[0] if self.pairings else None
        pairing = SenderPairing(self.node, self.node.resolve_topic_name(topic), self._source,
                                what=what, setting='step_source', follow=first)
        self.pairings.append(pairing)
        return pairing

    def subscription(self, msg_type: Any, topic: str, callback: Callable[[Any], None],
                     qos: Any, what: str) -> SenderSubscription:
        """A subscription of the step source's `topic` (paired like the steps)."""
        pairing = self._steps if topic == TOPICS.STEP else self.pairing(topic, what)
        subscription = SenderSubscription(self.node, msg_type, topic, qos, callback,
                                          admit=pairing.accepts)
        self._subscriptions.append(subscription)
        return subscription

    @property
    def refused(self) -> int:
        """Messages refused from publishers other than the step source."""
        return sum(pairing.refused for pairing in self.pairings)

    def errors(self) -> list[str]:
        """ERROR lines naming every other publisher on the step source's topics."""
        return [line for pairing in self.pairings for line in pairing.errors()]

    def destroy(self) -> None:
        """Our subscriptions are waitables: they go before the node (or a lifecycle cleanup).

        Never subscribes again afterwards (a pending `subscribe_when_heard` finds it done), and
        its pairings are no longer reported as peers.
        """
        for subscription in self._subscriptions:
            subscription.destroy()
        self._subscriptions.clear()
        self.subscribed = True
        unwatch_peers(self.node, self.pairings)

    def subscribe(self) -> None:
        """Subscribe to StepFeedback and the observation topic (once)."""
        if self.subscribed:
            return
        self.subscribed = True
        self._steps.pair()  # now, if the graph names the source; else at the first step
        self.subscription(StepFeedback, TOPICS.STEP, self._on_feedback, step_qos(), 'steps')
        if self.decoder.obs_kind == 'pixels':
            self.subscription(Image, TOPICS.IMAGE, self._on_image, image_qos(self.mode),
                              'frames')
        else:
            self.subscription(StateVector, TOPICS.STATE, self._on_state, step_qos(),
                              'observations')

    def subscribe_when_heard(self, output: Any, expected: int, timeout: float,
                             readers: Sequence[tuple[Any, int]] = ()) -> None:
        """Subscribe once the group can start without losing step 0 here (or after `timeout`).

        The step producer waits for its step subscribers (min_observers) before step 0, so a
        node that subscribes only once its readers and the recorder can hear its answer
        (publisher `output` matched `expected` subscribers) makes the whole group wait for
        them: a bag then holds this node's output from step 0. It also waits until the step
        source's publishers are discovered, so the subscriptions made here match them at once,
        and until its own `readers` (subscription, expected publishers) matched theirs
        (`unmatched_readers`). After `timeout` seconds it says what is still short and
        subscribes anyway.
        """
        if self.subscribed:
            return
        call_when_ready(self.node, lambda: self._short_of(output, expected, readers),
                        self.subscribe, timeout, 'subscriber_timeout',
                        'subscribing to the steps anyway: this node may miss the first steps')

    def _short_of(self, output: Any, expected: int,
                  readers: Sequence[tuple[Any, int]]) -> list[str]:
        """What subscribe_when_heard still waits for (empty: subscribe now)."""
        short = []
        matched = output.get_subscription_count()
        if matched < expected:
            short.append(f'{expected} subscribers of {output.topic_name} (expected_subscribers; '
                         f'{matched} matched so far)')
        observation = TOPICS.IMAGE if self.decoder.obs_kind == 'pixels' else TOPICS.STATE
        return short + unmatched_readers(self.node, readers, sources=(TOPICS.STEP, observation))

    def _on_feedback(self, msg: StepFeedback) -> None:
        self.assembler.add(msg.step, 'feedback', msg)
        if self.decoder.obs_kind == 'pixels':
            self._join.feedback(stamp_ns(msg.header.stamp), msg.step)

    def _on_state(self, msg: StateVector) -> None:
        try:
            raw = self.decoder.validate(msg)
        except ValueError as error:
            self.on_reject(msg.step, TOPICS.STATE, error)
            return
        self.assembler.add(msg.step, 'obs', (time.monotonic(), raw))

    def _on_image(self, msg: Image) -> None:
        # Images carry no step index: the join matches them to a step through the stamp.
        try:
            raw = self.decoder.validate(msg)
        except ValueError as error:
            self.on_reject(-1, TOPICS.IMAGE, error)
            return
        self._join.image(stamp_ns(msg.header.stamp), (time.monotonic(), raw))
