"""Intra-process delivery between the nodes of one process (the container), as rclcpp's.

Why: in `zeus launch --single-process` every message between sim_bridge, the estimator and the
policy went through DDS although all three live in one process: serialised, handed back to the
same process, taken, deserialised, each a turn of rclpy's executor. With a bus, a message that
a node of the container publishes is handed as the same Python object to the container's
subscribers of the same fully resolved topic (namespace and remaps applied) and type. It is
still published on DDS while anyone outside subscribes (recorder, zeus inspect, ros2 topic
echo); the container's own subscriptions are `SenderSubscription`s that drop the DDS copies of
the bus's publishers by their GID, unread, so no co-located node gets a message twice.

What is kept of DDS's semantics: each subscriber gets a publisher's messages in publish order;
its QoS history bounds its queue (keep-last N drops the oldest when it lags, keep-all none); a
best-effort publisher does not reach a reliable subscriber, nor a volatile one a
transient-local subscriber; a transient-local publisher stays off the bus (late joiners get its
history from DDS); a subscription's `admit` (the sender pairing) decides on the publisher's GID
as for a DDS message. As with rclcpp's shared messages, a subscriber must not modify a message
it receives (every co-located subscriber gets the same object) and a publisher must not modify
one it has published. Our nodes build a new message per publish and only read what they get.

Delivery runs on the executor (a task of it), never inside `publish()`: the lockstep chain
sim_bridge -> estimator -> policy -> sim_bridge would otherwise recurse without end. One turn
delivers for up to `budget` seconds (messages that callbacks publish meanwhile included), then
hands the executor back, so timers, parameter services and DDS get their turn. A task, not a
guard condition, so that rclpy's events executor (which serves no guard conditions) runs the
container too. The bus assumes one executor thread over its nodes (spin.run_nodes) and
delivers on the executor of the first node attached; messages published before that node is
on an executor wait for `wake()` (spin.make_executor calls it).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
import time
from typing import TYPE_CHECKING, Any

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from zeus_ros.nodes.rcl_bindings import publisher_gid
from zeus_ros.nodes.senders import SenderSubscription

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.publisher import Publisher
    from rclpy.qos import QoSProfile

__all__ = ['DRAIN_BUDGET', 'IntraProcessBus', 'IntraProcessNode', 'with_intra_process']

DRAIN_BUDGET = 0.01
"""Seconds one turn of the bus may deliver before the executor serves everything else."""


@dataclass(eq=False)
class _Endpoint:
    """One co-located subscription: its queue of (publisher GID, message), bounded by its QoS."""

    subscription: SenderSubscription
    queue: deque[tuple[bytes, Any]] = field(init=False)

    def __post_init__(self) -> None:
        qos = self.subscription.qos
        keep_last = qos.history != HistoryPolicy.KEEP_ALL and qos.depth > 0
        self.queue = deque(maxlen=qos.depth if keep_last else None)

    def reached_by(self, msg_type: Any, qos: QoSProfile) -> bool:
        """True where DDS would connect a publisher of this type and QoS to this subscription."""
        wants = self.subscription.qos
        return msg_type is self.subscription.msg_type and not (
            qos.reliability == ReliabilityPolicy.BEST_EFFORT
            and wants.reliability == ReliabilityPolicy.RELIABLE) and not (
            qos.durability == DurabilityPolicy.VOLATILE
            and wants.durability == DurabilityPolicy.TRANSIENT_LOCAL)


class IntraProcessBus:
    """Hands messages between the nodes of one process; counts what it delivered."""

    def __init__(self, budget: float = DRAIN_BUDGET) -> None:
        self.budget = budget
        self.gids: set[bytes] = set()
        """GIDs of the publishers on the bus: their DDS copies are dropped by bus subscribers."""
        self.delivered = 0
        self._topics: dict[str, list[_Endpoint]] = {}
        self._endpoints: dict[int, _Endpoint] = {}
        self._order: deque[_Endpoint] = deque()  # one entry per queued message, publish order
        self._host: Node | None = None  # the node whose executor runs the deliveries
        self._scheduled = False  # a delivery task is on the executor
        self._version = 0  # changes with the subscriptions: publishers recompute whom they reach

    def attach(self, node: Node) -> None:
        """Run the deliveries on `node`'s executor (that of the first node attached)."""
        if self._host is None:
            self._host = node

    def wake(self) -> None:
        """Schedule a delivery turn on the host's executor if messages wait and none is due."""
        executor = self._host.executor if self._host is not None else None
        if self._order and not self._scheduled and executor is not None:
            self._scheduled = True
            executor.create_task(self._drain)

    def add_publisher(self, publisher: Publisher) -> None:
        """Deliver what `publisher` publishes to the bus's subscribers of its topic in process.

        DDS gets the message only while it has subscribers outside the bus, as rclcpp
        decides: Fast DDS matches the endpoints of one participant as they are created, so
        the matched count minus the bus's subscribers it reaches is the count outside.
        """
        qos = publisher.qos_profile
        if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL:
            return  # late joiners need DDS's history of it
        gid = publisher_gid(publisher)
        self.gids.add(gid)  # kept after the publisher is gone: its copies may still be queued
        topic, msg_type = publisher.topic_name, publisher.msg_type
        dds_publish = publisher.publish
        reached: list[_Endpoint] = []
        seen = [-1]  # the bus's version `reached` was computed for

        def publish(msg: Any) -> None:
            if seen[0] != self._version:
                reached[:] = [endpoint for endpoint in self._topics.get(topic, ())
                              if endpoint.reached_by(msg_type, qos)]
                seen[0] = self._version
            if publisher.get_subscription_count() > len(reached):
                dds_publish(msg)  # someone outside subscribes (recorder, inspect, echo)
            elif not isinstance(msg, (msg_type, bytes)):
                raise TypeError(f'Expected {msg_type}, got {type(msg)}')  # as publish() says
            if isinstance(msg, bytes):
                msg = deserialize_message(msg, msg_type)
            self._enqueue(reached, gid, msg)

        publisher.publish = publish  # type: ignore[method-assign]

    def add_subscription(self, subscription: SenderSubscription) -> set[bytes]:
        """Deliver the bus's messages on its topic to `subscription`; return the GIDs to drop."""
        endpoint = _Endpoint(subscription)
        self._endpoints[id(subscription)] = endpoint
        self._topics.setdefault(subscription.topic_name, []).append(endpoint)
        self._version += 1
        return self.gids

    def remove_subscription(self, subscription: SenderSubscription) -> None:
        """Stop delivering to `subscription` (what is queued for it is dropped)."""
        endpoint = self._endpoints.pop(id(subscription), None)
        if endpoint is not None:
            endpoint.queue.clear()
            self._topics[subscription.topic_name].remove(endpoint)
            self._version += 1

    def _enqueue(self, endpoints: list[_Endpoint], gid: bytes, msg: Any) -> None:
        for endpoint in endpoints:
            endpoint.queue.append((gid, msg))  # a full keep-last queue drops its oldest
            self._order.append(endpoint)
        if endpoints:
            self.wake()

    def _drain(self) -> None:
        """Deliver in publish order for up to `budget` seconds; then leave the rest for later.

        Still marked scheduled while it runs: what the callbacks publish meanwhile is delivered
        by this loop, not by a second task that would find the queue empty.
        """
        order = self._order
        deadline = time.monotonic() + self.budget
        try:
            while order:
                endpoint = order.popleft()
                if endpoint.queue:  # empty: that message was dropped (depth) or the sub is gone
                    gid, msg = endpoint.queue.popleft()
                    subscription = endpoint.subscription
                    if subscription.admit(gid):
                        self.delivered += 1
                        subscription.deliver(msg, gid)
                if time.monotonic() >= deadline:
                    break
        finally:
            self._scheduled = False
            self.wake()  # what is left (the budget ran out, a callback raised) gets a turn


class IntraProcessNode:
    """Mixin of a container's node: its publishers and subscriptions join `intra_process`.

    Subscriptions are `SenderSubscription`s that admit every sender (a raw subscription or one
    with QoS overriding options stays rclpy's own, DDS only). Used through
    `with_intra_process`, never directly.
    """

    intra_process: IntraProcessBus

    def create_publisher(self, *args: Any, **kwargs: Any) -> Publisher:
        """The publisher rclpy makes, whose publish() also feeds the bus."""
        publisher = super().create_publisher(*args, **kwargs)  # type: ignore[misc]
        self.intra_process.attach(self)  # type: ignore[arg-type]
        self.intra_process.add_publisher(publisher)
        return publisher

    def create_subscription(self, msg_type: Any, topic: str, callback: Callable[[Any], None],
                            qos_profile: QoSProfile | int, *, callback_group: Any = None,
                            event_callbacks: SubscriptionEventCallbacks | None = None,
                            qos_overriding_options: Any = None, raw: bool = False) -> Any:
        """A subscription on the bus and on DDS (the DDS copies of bus messages dropped)."""
        if raw or qos_overriding_options is not None:
            return super().create_subscription(  # type: ignore[misc]
                msg_type, topic, callback, qos_profile, callback_group=callback_group,
                event_callbacks=event_callbacks, qos_overriding_options=qos_overriding_options,
                raw=raw)
        qos = self._validate_qos_or_depth_parameter(qos_profile)  # type: ignore[attr-defined]
        self.intra_process.attach(self)  # type: ignore[arg-type]
        subscription = SenderSubscription(
            self, msg_type, topic, qos, callback, admit=_anyone,  # type: ignore[arg-type]
            callback_group=callback_group,
            event_callbacks=event_callbacks or SubscriptionEventCallbacks())
        self.__dict__.setdefault('_intra_subscriptions', []).append(subscription)
        return subscription

    def destroy_subscription(self, subscription: Any) -> bool:
        """Also destroys the bus's subscriptions."""
        if isinstance(subscription, SenderSubscription):
            subscription.destroy()
            return True
        return super().destroy_subscription(subscription)  # type: ignore[misc]

    def destroy_node(self) -> None:
        """The bus's subscriptions are waitables: they go before the node."""
        for subscription in self.__dict__.get('_intra_subscriptions', []):
            subscription.destroy()
        super().destroy_node()  # type: ignore[misc]


def _anyone(_gid: bytes) -> bool:
    return True


def with_intra_process(node_class: type[Node], bus: IntraProcessBus) -> type[Node]:
    """`node_class` whose instances deliver through `bus` (same name, same behaviour)."""
    return type(node_class.__name__, (IntraProcessNode, node_class), {'intra_process': bus})
