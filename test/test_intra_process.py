"""Intra-process delivery between the nodes of one process (nodes/intra_process.py), real rclpy.

The "container" is a context of the test process whose nodes share one bus; "outside" is a
second context (another DDS participant) on the same domain: what a recorder or `ros2 topic
echo` sees.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
import contextlib
import time
from typing import Any

import pytest

from ros_harness import fresh_domain_id, require_ros, ros_context

pytestmark = pytest.mark.ros
TOPIC = 'zeus/observation/state'


@contextlib.contextmanager
def two_contexts(bus: bool = True, executor: str = 'single'
                 ) -> Iterator[tuple[Callable[..., Any], Callable[..., Any],
                                     Callable[[Callable[[], bool], float], bool]]]:
    """(make a container node, make an outside node, spin both until a predicate or timeout).

    `executor`: what the container's context spins on ('single' or 'events', as
    spin.make_executor builds them; outside: single-threaded).
    """
    require_ros()
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from zeus_ros.nodes.intra_process import IntraProcessBus, with_intra_process
    from zeus_ros.nodes.spin import make_executor

    domain = fresh_domain_id()
    opened = contextlib.ExitStack()
    contexts = [opened.enter_context(ros_context(domain)) for _ in range(2)]
    executors = [make_executor([], executor, context=contexts[0]),
                 SingleThreadedExecutor(context=contexts[1])]
    node_class = with_intra_process(Node, IntraProcessBus()) if bus else Node
    nodes: list[Any] = []

    def make(which: int, name: str, **options: Any) -> Any:
        node = (node_class if which == 0 else Node)(name, context=contexts[which], **options)
        executors[which].add_node(node)
        nodes.append(node)
        return node

    def spin(predicate: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return False
            for executor in executors:
                executor.spin_once(timeout_sec=0.01)
        return True

    try:
        yield (lambda name, **o: make(0, name, **o)), (lambda name, **o: make(1, name, **o)), spin
    finally:
        for node in nodes:
            node.destroy_node()
        for executor in executors:
            executor.shutdown()
        opened.close()


def state(step: int) -> Any:
    """A StateVector for `step` (its step index tells the messages apart)."""
    from zeus_msgs.msg import StateVector

    return StateVector(step=step, data=[float(step)])


def same_objects(got: list[Any], sent: list[Any]) -> bool:
    """True when `got` holds exactly the objects of `sent`, in order (no copies)."""
    return len(got) == len(sent) and all(a is b for a, b in zip(got, sent, strict=True))


def settle(spin: Callable[[Callable[[], bool], float], bool], seconds: float = 1.0) -> None:
    """Spin for `seconds`: every DDS copy there is to drop has arrived and been taken."""
    spin(lambda: False, seconds)


def publish_states(talker: Any, spin: Callable[..., bool], readers: int, count: int
                   ) -> list[Any]:
    """Once `talker` has matched `readers` subscriptions, publish states 0..count-1 (returned)."""
    assert spin(lambda: talker.get_subscription_count() == readers, 20), 'no DDS match'
    sent = [state(step) for step in range(count)]
    for msg in sent:
        talker.publish(msg)
    return sent


@pytest.mark.parametrize('executor', ['single', 'events'])
def test_co_located_subscriber_gets_each_message_once_as_the_published_object(
        executor: str) -> None:
    """In process: the very objects, in order, once each; outside: every message via DDS.

    Under both executors (the bus runs as executor tasks: the events executor has no guard
    conditions).
    """
    from zeus_msgs.msg import StateVector

    from zeus_ros.nodes.topics import step_qos

    with two_contexts(executor=executor) as (inside, outside, spin):
        talker = inside('sim_bridge').create_publisher(StateVector, TOPIC, step_qos(50))
        local: list[Any] = []
        remote: list[int] = []
        inside('policy').create_subscription(StateVector, TOPIC, local.append, step_qos(50))
        outside('recorder').create_subscription(StateVector, TOPIC,
                                                lambda m: remote.append(m.step), step_qos(50))
        sent = publish_states(talker, spin, 2, 30)
        assert spin(lambda: len(remote) == 30 and len(local) == 30, 20), (len(local), remote)
        settle(spin)
        assert [m.step for m in local] == list(range(30)), 'a DDS copy came through as well'
        assert same_objects(local, sent), 'not handed over in process'
        assert remote == list(range(30))


def test_without_the_bus_messages_between_nodes_of_a_process_go_through_dds() -> None:
    """The switch off (--no-intra-process): copies from DDS, still once each."""
    from zeus_msgs.msg import StateVector

    from zeus_ros.nodes.topics import step_qos

    with two_contexts(bus=False) as (inside, _outside, spin):
        talker = inside('sim_bridge').create_publisher(StateVector, TOPIC, step_qos(50))
        local: list[Any] = []
        inside('policy').create_subscription(StateVector, TOPIC, local.append, step_qos(50))
        sent = publish_states(talker, spin, 1, 10)
        assert spin(lambda: len(local) == 10, 20)
        settle(spin, 0.3)
        assert [m.step for m in local] == list(range(10))
        assert not any(got is msg for got, msg in zip(local, sent, strict=True))


@pytest.mark.parametrize('executor', ['single', 'events'])
def test_keep_last_depth_drops_the_oldest_for_a_subscriber_that_lags(executor: str) -> None:
    """20 messages before the executor runs: depth 5 keeps the newest 5, depth 50 all 20."""
    from zeus_msgs.msg import StateVector

    from zeus_ros.nodes.topics import step_qos

    with two_contexts(executor=executor) as (inside, _outside, spin):
        talker = inside('sim_bridge').create_publisher(StateVector, TOPIC, step_qos(50))
        shallow: list[int] = []
        deep: list[int] = []
        inside('shallow').create_subscription(StateVector, TOPIC,
                                              lambda m: shallow.append(m.step), step_qos(5))
        inside('deep').create_subscription(StateVector, TOPIC,
                                           lambda m: deep.append(m.step), step_qos(50))
        assert spin(lambda: talker.get_subscription_count() == 2, 20), 'no DDS match'
        for step in range(20):
            talker.publish(state(step))
        assert spin(lambda: len(deep) == 20, 20), deep
        settle(spin)
        assert shallow == list(range(15, 20))
        assert deep == list(range(20))


def test_namespaces_and_remaps_decide_who_is_connected() -> None:
    """Same resolved name after remapping: delivered; another namespace: not."""
    from zeus_msgs.msg import StateVector

    from zeus_ros.nodes.topics import step_qos

    with two_contexts() as (inside, _outside, spin):
        talker = inside('sim_bridge', namespace='/r1').create_publisher(
            StateVector, 'zeus/out', step_qos(50))
        remapped: list[Any] = []
        elsewhere: list[Any] = []
        inside('policy', namespace='/r1',
               cli_args=['--ros-args', '-r', 'zeus/in:=zeus/out']).create_subscription(
            StateVector, 'zeus/in', remapped.append, step_qos(50))
        inside('policy', namespace='/r2').create_subscription(
            StateVector, 'zeus/out', elsewhere.append, step_qos(50))
        sent = publish_states(talker, spin, 1, 5)
        assert spin(lambda: len(remapped) == 5, 20)
        settle(spin, 0.5)
        assert same_objects(remapped, sent)
        assert elsewhere == []


def test_outside_publishers_still_reach_co_located_subscribers() -> None:
    """Only the bus's own publishers' DDS copies are dropped."""
    from zeus_msgs.msg import StateVector

    from zeus_ros.nodes.topics import step_qos

    with two_contexts() as (inside, outside, spin):
        local: list[int] = []
        inside('policy').create_subscription(StateVector, TOPIC,
                                             lambda m: local.append(m.step), step_qos(50))
        inside('sim_bridge').create_publisher(StateVector, TOPIC, step_qos(50))
        stranger = outside('stranger').create_publisher(StateVector, TOPIC, step_qos(50))
        assert spin(lambda: stranger.get_subscription_count() == 1, 20), 'no DDS match'
        for step in range(5):
            stranger.publish(state(step))
        assert spin(lambda: len(local) == 5, 20)
        assert local == list(range(5))


def test_best_effort_publisher_does_not_reach_a_reliable_subscriber() -> None:
    """QoS that DDS would not connect is not connected in process either."""
    from rclpy.qos import qos_profile_sensor_data
    from zeus_msgs.msg import StateVector

    from zeus_ros.nodes.topics import step_qos

    with two_contexts() as (inside, _outside, spin):
        talker = inside('sim_bridge').create_publisher(StateVector, TOPIC,
                                                       qos_profile_sensor_data)
        reliable: list[int] = []
        best_effort: list[int] = []
        inside('reliable').create_subscription(StateVector, TOPIC,
                                               lambda m: reliable.append(m.step), step_qos(50))
        inside('sensor').create_subscription(StateVector, TOPIC,
                                             lambda m: best_effort.append(m.step),
                                             qos_profile_sensor_data)
        assert spin(lambda: talker.get_subscription_count() == 1, 20), 'no DDS match'
        talker.publish(state(7))
        assert spin(lambda: best_effort == [7], 20)
        settle(spin, 0.5)
        assert reliable == []


def test_sim_time_nodes_follow_clock_in_process_and_can_turn_it_off() -> None:
    """use_sim_time: rclpy's /clock subscription joins the bus; turning it off destroys it."""
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock

    from zeus_ros.nodes.messages import stamp_from_seconds
    from zeus_ros.nodes.topics import TOPICS, step_qos

    with two_contexts() as (inside, _outside, spin):
        clock = inside('sim_bridge').create_publisher(Clock, TOPICS.CLOCK, step_qos())
        follower = inside('policy', parameter_overrides=[
            Parameter('use_sim_time', Parameter.Type.BOOL, True)])
        assert spin(lambda: clock.get_subscription_count() == 1, 20), 'no DDS match'
        clock.publish(Clock(clock=stamp_from_seconds(12.5)))
        assert spin(lambda: follower.get_clock().now().nanoseconds == 12_500_000_000, 20)
        follower.set_parameters([Parameter('use_sim_time', Parameter.Type.BOOL, False)])
        assert spin(lambda: clock.get_subscription_count() == 0, 20), 'still subscribed'
