"""Start-up on a shared graph: counting peers, and waiting for them before step 0.

A node that starts before its peers are discovered and matched would drop step 0 for a late
one; these helpers say what is still missing, wait on the steady clock (they run before /clock
moves) and name a wait that lasts.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import math
import time
from typing import TYPE_CHECKING, Any

from rclpy.clock import Clock, ClockType

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.timer import Timer

__all__ = [
    'WaitReport',
    'call_when_ready',
    'count_publishers',
    'count_subscribers',
    'missing_peers',
    'steady_timer',
    'unmatched_readers',
]


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
