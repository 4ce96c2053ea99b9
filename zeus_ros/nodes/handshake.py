"""Who a restarted peer is: every node's start hello (name, nonce, checkpoint, publishers).

Why: pairing by publisher GID (senders.py) refuses a second publisher, but a node that comes
back after a crash publishes under a new GID and the same name, and a name is all an impostor
needs to claim. So each zeus node announces itself once per start on `zeus/pairing` (transient
local, so a late joiner gets it): its fully qualified name, a random start nonce, the sha256 of
its checkpoint ('' for none) and the GIDs of its publishers; with `$ZEUS_PAIRING_KEY` set (the
launch file and `zeus launch` set one per launch) also an HMAC of these under the key. A
consumer re-pairs with a newcomer under the paired node's name only when a hello lists the
newcomer's GID, carries a start nonce other than the one agreed at pairing, the same checkpoint
sha256, and (with a key) a proof that checks: an explicit handshake, never the name alone.

Without a key this stops mistakes and stray processes (a test script, a node started by hand
under a taken name), not an attacker who runs our own node code; with a key, only processes
started with the launch's environment re-pair; SROS2 keeps the rest off the domain
(docs/security.md).
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
import hmac
import json
import os
import secrets
import time
from typing import TYPE_CHECKING

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

if TYPE_CHECKING:
    from collections.abc import Callable

    from rclpy.node import Node

__all__ = ['KEY_ENV', 'PAIRING_TOPIC', 'Handshake', 'Hello', 'handshake_of', 'new_key']

PAIRING_TOPIC = 'zeus/pairing'
"""Relative: a namespaced system hears only its own nodes' hellos."""
KEY_ENV = 'ZEUS_PAIRING_KEY'
"""The environment variable holding the launch's shared key (hex; empty: no proofs)."""
_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                  reliability=ReliabilityPolicy.RELIABLE,
                  durability=DurabilityPolicy.TRANSIENT_LOCAL)
RESEND_S = 1.0
"""Seconds between two sends of an unchanged hello."""
_KEPT = 4096  # GIDs remembered (a node restarting a hundred times forgets its oldest ones)


def new_key() -> str:
    """A fresh launch key for `$ZEUS_PAIRING_KEY` (128 random bits, hex)."""
    return secrets.token_hex(16)


@dataclass(frozen=True)
class Hello:
    """One node's announcement of one start."""

    node: str
    nonce: str
    sha256: str
    gids: frozenset[str]  # hex GIDs of its publishers
    proof: str = ''

    def _body(self) -> bytes:
        return json.dumps([self.node, self.nonce, self.sha256, sorted(self.gids)]).encode()

    def signed(self, key: bytes) -> Hello:
        """The same hello with its proof under `key` (none without a key)."""
        proof = hmac.new(key, self._body(), hashlib.sha256).hexdigest() if key else ''
        return Hello(self.node, self.nonce, self.sha256, self.gids, proof)

    def verified(self, key: bytes) -> bool:
        """True without a key; with one, when the proof is the key's."""
        return not key or hmac.compare_digest(self.signed(key).proof, self.proof)

    def to_text(self) -> str:
        """The JSON carried in a std_msgs/String."""
        return json.dumps({'node': self.node, 'nonce': self.nonce, 'sha256': self.sha256,
                           'gids': sorted(self.gids), 'proof': self.proof})

    @staticmethod
    def from_text(text: str) -> Hello | None:
        """The hello in `text`, or None for anything malformed (never trusted, never raised)."""
        try:
            data = json.loads(text)
            return Hello(str(data['node']), str(data['nonce']), str(data['sha256']),
                         frozenset(map(str, data['gids'])), str(data.get('proof', '')))
        except (ValueError, KeyError, TypeError):
            return None


class Handshake:
    """The node's own hello out; the peers' hellos in, by the GIDs they list.

    `sha256` says the node's checkpoint now (a live redeploy re-announces it under the same
    nonce). The hello is sent again when the node's publishers or checkpoint change (checked
    every `period` seconds on the steady clock) and every `RESEND_S` seconds anyway: a late
    reader gets a transient-local sample only after the writer's next heartbeat (Fast DDS:
    3 s), and a restarted peer must not wait that long to be re-paired.
    """

    def __init__(self, node: Node, period: float = 0.25) -> None:
        from zeus_ros.nodes.peers import steady_timer

        self._node = node
        self.name = node.get_fully_qualified_name()
        self.key = os.environ.get(KEY_ENV, '').strip().encode()
        self.nonce = secrets.token_hex(8)
        self.sha256: Callable[[], str] = lambda: ''
        self._by_gid: dict[str, Hello] = {}
        self._sent: tuple[int, str] = (-1, '')
        self._sent_at = -RESEND_S
        self.malformed = 0
        self._pub = node.create_publisher(String, PAIRING_TOPIC, _QOS)
        self._sub = node.create_subscription(String, PAIRING_TOPIC, self._on_hello, _QOS)
        steady_timer(node, period, self.announce)

    def announce(self) -> None:
        """Send this start's hello if it changed, or if it was last sent RESEND_S ago."""
        from zeus_ros.nodes.rcl_bindings import publisher_gid

        publishers = list(self._node.publishers)
        sha256 = self.sha256()
        now = time.monotonic()
        if (len(publishers), sha256) == self._sent and now - self._sent_at < RESEND_S:
            return
        gids = []
        for publisher in publishers:
            try:
                gids.append(publisher_gid(publisher).hex())
            except Exception:  # a publisher being destroyed (InvalidHandle): next turn
                return
        hello = Hello(self.name, self.nonce, sha256, frozenset(gids)).signed(self.key)
        self._pub.publish(String(data=hello.to_text()))
        self._sent, self._sent_at = (len(publishers), sha256), now

    def _on_hello(self, msg: String) -> None:
        hello = Hello.from_text(msg.data)
        if hello is None:
            self.malformed += 1
            return
        for gid in hello.gids:
            self._by_gid[gid] = hello
        while len(self._by_gid) > _KEPT:
            del self._by_gid[next(iter(self._by_gid))]

    def hello_of(self, gid: bytes) -> Hello | None:
        """The newest hello that lists publisher `gid` (None: none heard)."""
        return self._by_gid.get(gid.hex())

    def introduces(self, gid: bytes, node: str, agreed: Hello | None) -> str | None:
        """Why publisher `gid` of `node` may not replace the `agreed` peer (None: it may).

        It may when its own hello lists it under `node`, with a start nonce other than the
        agreed one, the agreed checkpoint sha256, and (with a key) a proof that checks.
        """
        hello = self.hello_of(gid)
        if agreed is None:
            return 'no hello of the paired node was heard at pairing, so no restart is believed'
        if hello is None:
            return 'it sent no hello (zeus/pairing) listing this publisher'
        if hello.node != node:
            return f'its hello names {hello.node}, the graph {node}'
        if hello.nonce == agreed.nonce:
            return 'its hello repeats the start nonce of the paired node (a replay)'
        if hello.sha256 != agreed.sha256:
            return (f'its checkpoint sha256 {hello.sha256[:12] or "(none)"} is not the pair\'s '
                    f'{agreed.sha256[:12] or "(none)"}')
        if not hello.verified(self.key):
            return f'its hello has no valid proof of the launch key (${KEY_ENV})'
        return None


def handshake_of(node: Node) -> Handshake:
    """The one Handshake of `node` (made on first use)."""
    handshake = node.__dict__.get('_zeus_handshake')
    if handshake is None:
        handshake = node.__dict__['_zeus_handshake'] = Handshake(node)
    return handshake
