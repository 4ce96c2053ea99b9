"""A node that poses as one of ours: the fault matrix's spoofer and injector.

`python impostor.py NODE_NAME KIND SECONDS [SHA256]` starts a node named NODE_NAME (e.g.
`policy`, taking the real policy's name) that follows zeus/step and publishes, every 5 ms,
what KIND says (once a subscriber has matched), each value MARK so a use of it is
recognisable:
action (for the awaited step), context (for the current step, stamped with SHA256: a copy
of the real pair's hash), observation (state vectors and step feedback for steps far ahead,
INJECTED_STEP + n, so any action answering one is recognisable). With KIND `action+hello` it
also sends a start hello as a restart of NODE_NAME would (its own publishers' GIDs, a fresh
nonce, SHA256 as the checkpoint's, no key: the unkeyed stall takeover of issue 49). It prints
`posing` once its publisher exists and `published N` at the end.
"""

from __future__ import annotations

import os
import secrets
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from zeus_msgs.msg import Action, ContextEstimate, StateVector, StepFeedback

from zeus_ros.nodes.topics import TOPICS, step_qos

MARK = 0.4321
INJECTED_STEP = 1_000_000
SIZES = {'action': 6, 'context': 10, 'observation': 17}  # Cheetah-Run-v0, tiny checkpoint


def main(name: str, kind: str, seconds: float, sha256: str = '') -> int:
    """Pose for `seconds`; return 0."""
    rclpy.init()
    node = rclpy.create_node(name)
    newest = {'step': 0}
    node.create_subscription(StepFeedback, TOPICS.STEP,
                             lambda m: newest.__setitem__('step', max(m.step, newest['step'])
                                                          if m.step < INJECTED_STEP
                                                          else newest['step']), step_qos())
    hello = kind.endswith('+hello')
    kind = kind.removesuffix('+hello')
    data = [MARK] * SIZES[kind]
    if kind == 'action':
        publishers = [(node.create_publisher(Action, TOPICS.ACTION, step_qos()),
                       lambda step: Action(step=step, data=data))]
    elif kind == 'context':
        publishers = [(node.create_publisher(ContextEstimate, TOPICS.CONTEXT, step_qos()),
                       lambda step: ContextEstimate(step=step, data=data,
                                                    checkpoint_sha256=sha256))]
    else:
        publishers = [(node.create_publisher(StepFeedback, TOPICS.STEP, step_qos()),
                       lambda step: StepFeedback(step=INJECTED_STEP + step, episode=0,
                                                 first=False, applied_action=[0.0] * 6)),
                      (node.create_publisher(StateVector, TOPICS.STATE, step_qos()),
                       lambda step: StateVector(step=INJECTED_STEP + step, data=data))]
    if hello:
        _send_hello(node, sha256)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    matched = time.monotonic() + 20  # the victims hear it first (a loaded machine is slow)
    while time.monotonic() < matched and min(
            publisher.get_subscription_count() for publisher, _build in publishers) == 0:
        executor.spin_once(timeout_sec=0.05)
    print('posing', flush=True)
    published = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.005)
        for publisher, build in publishers:
            publisher.publish(build(newest['step']))
            published += 1
    print(f'published {published}', flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def _send_hello(node: Node, sha256: str) -> None:
    """Announce `node` as a restart of its name would: a checked hello, only the key missing."""
    from zeus_msgs.msg import PairingHello

    from zeus_ros.nodes.handshake import PAIRING_TOPIC, QOS, Hello
    from zeus_ros.nodes.rcl_bindings import publisher_gid

    publisher = node.create_publisher(PairingHello, PAIRING_TOPIC, QOS)
    gids = frozenset(publisher_gid(p).hex() for p in node.publishers)
    forged = Hello(node.get_fully_qualified_name(), secrets.token_hex(8), sha256, gids,
                   pid=os.getpid())
    publisher.publish(forged.to_msg())


if __name__ == '__main__':
    raise SystemExit(main(sys.argv[1], sys.argv[2], float(sys.argv[3]), *sys.argv[4:]))
