"""What a paired topic costs: rclpy's own subscription against a SenderSubscription.

Every topic a zeus node consumes is taken as a `SenderSubscription` (nodes/senders.py), which
sees each message's publisher GID: a waitable that takes through rcl with ctypes. This measures
the CPU per message (publish, take, callback) of both on the events executor, in one process,
alternately, so a busy machine weighs on both alike.

    source scripts/env.sh && python benchmarks/bench_paired_take.py [--messages 3000]
"""

from __future__ import annotations

import argparse
import time
from typing import Any


def cost_us(kind: str, messages: int, domain: int) -> float:
    """CPU microseconds per StateVector of 17 values through one subscription of `kind`."""
    import rclpy
    from zeus_msgs.msg import StateVector

    from zeus_ros.nodes.senders import SenderSubscription
    from zeus_ros.nodes.spin import make_executor
    from zeus_ros.nodes.topics import step_qos
    from zeus_ros.system.processes import ros_context

    with ros_context(domain) as context:
        talker = rclpy.create_node('talker', context=context)
        listener = rclpy.create_node('listener', context=context)
        got: list[Any] = []
        if kind == 'rclpy':
            listener.create_subscription(StateVector, 't', got.append, step_qos(100))
        else:
            SenderSubscription(listener, StateVector, 't', step_qos(100), got.append,
                               admit=lambda _gid: True)
        publisher = talker.create_publisher(StateVector, 't', step_qos(100))
        executor = make_executor([listener], 'events', context=context)
        while publisher.get_subscription_count() < 1:
            executor.spin_once(timeout_sec=0.01)
        msg = StateVector(step=1, data=[0.1] * 17)
        start = time.process_time()
        for index in range(messages):
            publisher.publish(msg)
            while len(got) <= index:
                executor.spin_once(timeout_sec=0.1)
        return (time.process_time() - start) / messages * 1e6


def main() -> None:
    """Print the cost of each kind, twice, alternately."""
    from zeus_ros.system.processes import fresh_domain_id

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--messages', type=int, default=3000)
    args = parser.parse_args()
    domain = fresh_domain_id()
    for kind in ('rclpy', 'paired', 'rclpy', 'paired'):
        print(f'{kind:7s} {cost_us(kind, args.messages, domain):6.1f} us CPU per message '
              '(publish + take + callback)', flush=True)


if __name__ == '__main__':
    main()
