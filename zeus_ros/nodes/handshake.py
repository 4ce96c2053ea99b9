"""Who a restarted peer is: every node's start hello (name, nonce, checkpoint, publishers).

Why: pairing by publisher GID (senders.py) refuses a second publisher, but a node that comes
back after a crash publishes under a new GID and the same name, and a name is all an impostor
needs to claim. So each zeus node announces itself once per start on `zeus/pairing`
(zeus_msgs/msg/PairingHello, transient local, so a late joiner gets it): its fully qualified
name, a random start nonce, the sha256 of its checkpoint ('' for none), its pid and the GIDs
of its publishers; with `$ZEUS_PAIRING_KEY` set (the launch file and `zeus launch` set one
per launch) also an HMAC of these under the key. A consumer re-pairs with a newcomer under
the paired node's name only when a hello lists the newcomer's GID, carries a start nonce
other than the one agreed at pairing, the same checkpoint sha256, and (with a key) a proof
that checks: an explicit handshake, never the name alone.

A hello is checked when it arrives, not when it is used, and is stored only if it passes: it
must list its own sender (the publisher GID of the message, which a process cannot choose), list
only publishers of its sender's DDS participant (a GID is a 12-byte participant prefix and a
4-byte entity id), and with a key carry the key's proof; one with an empty name or nonce, no
GID, or a GID that is not 16 bytes of hex is malformed (refused and counted too). So a
bystander that re-publishes the hellos it hears (another nonce, another sha256) or claims
another node's GIDs changes nothing a pairing reads: the pair's reference is only ever
written by the paired node's own process. Each refused hello is counted and its sender named
(full GID, the node the graph gives it, the pid its hello claims) in the log and, for 5 s, as
an ERROR on /diagnostics.

Without a key ('unkeyed', said once as a WARN at start and on /diagnostics) this stops
mistakes and stray processes (a test script, a node started by hand under a taken name), not
an attacker who runs our own node code; with a key, only processes started with the launch's
environment re-pair; SROS2 keeps the rest off the domain (docs/security.md).
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
import hmac
import json
import os
import re
import secrets
import time
from typing import TYPE_CHECKING, Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from zeus_msgs.msg import PairingHello

from zeus_ros.nodes.rcl_bindings import GID_SIZE

if TYPE_CHECKING:
    from collections.abc import Callable

    from rclpy.node import Node

__all__ = ['KEY_ENV', 'PAIRING_TOPIC', 'QOS', 'Handshake', 'Hello', 'MalformedHelloError',
           'Refusal', 'handshake_of', 'new_key', 'pairing_diagnostics', 'participant']

PAIRING_TOPIC = 'zeus/pairing'
"""Relative: a namespaced system hears only its own nodes' hellos."""
KEY_ENV = 'ZEUS_PAIRING_KEY'
"""The environment variable holding the launch's shared key (hex; empty: no proofs)."""
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                 reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""The hellos' QoS: transient local, so a late joiner gets each node's newest."""
RESEND_S = 1.0
"""Seconds between two sends of an unchanged hello."""
_KEPT = 4096  # GIDs remembered (a node restarting a hundred times forgets its oldest ones)
_GID_HEX = re.compile(f'[0-9a-f]{{{2 * GID_SIZE}}}')
_PREFIX = 12  # bytes of a DDS GUID (the rmw's GID) that name the participant
_NAME_WAIT_S = 2.0  # how long a refusal's log line waits for the graph to name its sender
ERROR_WINDOW_S = 5.0  # a refused sender stays an ERROR on /diagnostics this long after a hello
_REPEAT_S = 30.0  # a sender that goes on: one line per this many seconds with its count
_UNKNOWN_NODE = '_NODE_NAME_UNKNOWN_'  # rmw_dds_common's name before the node is announced
_warned_unkeyed = False  # the unkeyed WARN is said once per process


def participant(gid: bytes) -> bytes:
    """The DDS participant (process or rcl context) of publisher `gid`: its GUID prefix.

    Fast DDS and Cyclone DDS make the rmw GID from the writer's GUID: 12 bytes of participant
    prefix, then 4 of entity id (the entity ids repeat across processes: `...00001303` is the
    same publisher slot in every node). A process cannot publish under another's prefix.
    """
    return gid[:_PREFIX]


def new_key() -> str:
    """A fresh launch key for `$ZEUS_PAIRING_KEY` (128 random bits, hex)."""
    return secrets.token_hex(16)


@dataclass(frozen=True)
class Hello:
    """One node's announcement of one start (on the wire: zeus_msgs/msg/PairingHello)."""

    node: str
    nonce: str
    sha256: str
    gids: frozenset[str]  # hex GIDs of its publishers
    proof: str = ''
    pid: int = 0  # the process that sent it (0: not said); proven only with the key

    def _body(self) -> bytes:
        """What the proof covers: every field but the proof, in one fixed order."""
        return json.dumps([self.node, self.nonce, self.sha256, sorted(self.gids),
                           self.pid]).encode()

    def signed(self, key: bytes) -> Hello:
        """The same hello with its proof under `key` (none without a key)."""
        proof = hmac.new(key, self._body(), hashlib.sha256).hexdigest() if key else ''
        return Hello(self.node, self.nonce, self.sha256, self.gids, proof, self.pid)

    def verified(self, key: bytes) -> bool:
        """True without a key; with one, when the proof is the key's."""
        return not key or hmac.compare_digest(self.signed(key).proof, self.proof)

    def to_msg(self) -> PairingHello:
        """The message sent on zeus/pairing (GIDs sorted, as the proof covers them)."""
        return PairingHello(node=self.node, nonce=self.nonce, checkpoint_sha256=self.sha256,
                            pid=self.pid, publisher_gids=sorted(self.gids), proof=self.proof)

    @staticmethod
    def from_msg(msg: PairingHello) -> Hello:
        """The hello `msg` carries; MalformedHelloError says why it is not one.

        Why: the middleware checks only the types; an empty name or nonce, no publisher, or a
        GID that is not GID_SIZE bytes as lowercase hex would otherwise reach the checks (or
        be stored under a key no publisher has).
        """
        if not msg.node.startswith('/'):
            raise MalformedHelloError(f'node {msg.node!r} is not a fully qualified name')
        if not msg.nonce:
            raise MalformedHelloError('its start nonce is empty')
        if not msg.publisher_gids:
            raise MalformedHelloError('it lists no publisher GID')
        bad = [gid for gid in msg.publisher_gids if not _GID_HEX.fullmatch(gid)]
        if bad:
            raise MalformedHelloError(f'GID {bad[0][:80]!r} is not {GID_SIZE} bytes as '
                                      'lowercase hex')
        return Hello(msg.node, msg.nonce, msg.checkpoint_sha256, frozenset(msg.publisher_gids),
                     msg.proof, int(msg.pid))


class MalformedHelloError(ValueError):
    """A PairingHello that is not a hello at all (refused and counted as malformed)."""


@dataclass
class Refusal:
    """The hellos refused from one sender (a publisher on zeus/pairing)."""

    sender: bytes
    why: str
    claims: str  # what its newest hello says of itself (node, pid): unproven
    count: int = 0
    first: float = 0.0
    last: float = 0.0
    logged: float = -1.0  # when its line was last logged (-1: never)
    logged_count: int = 0
    name: str = ''  # its node, as the graph names the sender ('' until known)


class Handshake:
    """The node's own hello out; the peers' hellos in, checked on receipt, by the GIDs they list.

    `sha256` says the node's checkpoint now (a live redeploy re-announces it under the same
    nonce). The hello is sent again when the node's publishers or checkpoint change (checked
    every `period` seconds on the steady clock) and every `RESEND_S` seconds anyway: a late
    reader gets a transient-local sample only after the writer's next heartbeat (Fast DDS:
    3 s), and a restarted peer must not wait that long to be re-paired. `refused` counts the
    hellos that failed `check` (never stored); `errors()` names their senders.
    """

    def __init__(self, node: Node, period: float = 0.25) -> None:
        from zeus_ros.nodes.peers import steady_timer
        from zeus_ros.nodes.sender_subscription import SenderSubscription

        self._node = node
        self.name = node.get_fully_qualified_name()
        self.key = os.environ.get(KEY_ENV, '').strip().encode()
        self.nonce = secrets.token_hex(8)
        self.sha256: Callable[[], str] = lambda: ''
        self.urgent: Callable[[], None] = lambda: None
        """Publishes the node's /diagnostics now: called when a sender starts being refused,
        so its ERROR goes out at once rather than at the next 1-s tick (diagnostic_updater's
        force_update)."""
        self._by_gid: dict[str, Hello] = {}
        self._sent: tuple[int, str] = (-1, '')
        self._sent_at = -RESEND_S
        self.malformed = 0
        self.refused = 0
        self.refusals: dict[bytes, Refusal] = {}
        self._pub = node.create_publisher(PairingHello, PAIRING_TOPIC, QOS)
        self._sub = SenderSubscription(node, PairingHello, PAIRING_TOPIC, QOS, self._on_hello,
                                       admit=lambda _gid: True, with_sender=True)
        global _warned_unkeyed
        if not self.key and not _warned_unkeyed:  # once per process (a container: per group)
            _warned_unkeyed = True
            node.get_logger().warning(
                f'unkeyed pairing (${KEY_ENV} is blank): a restarted peer is re-paired only '
                'after its old publisher has left the ROS graph, and after a peer died any '
                'local process may pose as its restart. `zeus launch` and the launch file set '
                'a key; docs/security.md says what each mode promises')
        steady_timer(node, period, self.announce)

    @property
    def mode(self) -> str:
        """'keyed' (restarts need the launch key's proof) or 'unkeyed' (/diagnostics)."""
        return 'keyed' if self.key else 'unkeyed'

    def destroy(self) -> None:
        """Free the hello subscription (ours, not rclpy's): before the node is destroyed."""
        self._sub.destroy()

    def announce(self) -> None:
        """Send this start's hello if it changed, or if it was last sent RESEND_S ago."""
        from zeus_ros.nodes.rcl_bindings import publisher_gid

        self._log_refusals()
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
        hello = Hello(self.name, self.nonce, sha256, frozenset(gids),
                      pid=os.getpid()).signed(self.key)
        self._pub.publish(hello.to_msg())
        self._sent, self._sent_at = (len(publishers), sha256), now

    def check(self, hello: Hello, sender: bytes) -> str | None:
        """Why `hello`, sent by publisher `sender`, may not be believed (None: it may).

        Its sender must be among the publishers it lists (else it is relayed: a bystander
        re-publishing what it heard), every publisher it lists must belong to the sender's
        own participant (else it claims another process's publishers), and with a key its
        proof must be the key's.
        """
        if sender.hex() not in hello.gids:
            return ('it does not list its own sender: a relayed or forged hello (a node '
                    'announces only its own publishers)')
        foreign = sorted(gid for gid in hello.gids
                         if participant(bytes.fromhex(gid)) != participant(sender))
        if foreign:
            return (f'it claims {len(foreign)} publisher(s) of another process (gid '
                    f'{foreign[0]})')
        if not hello.verified(self.key):
            return f'it has no valid proof of the launch key (${KEY_ENV})'
        return None

    def _on_hello(self, msg: PairingHello, sender: bytes) -> None:
        try:
            hello = Hello.from_msg(msg)
        except MalformedHelloError as error:
            self.malformed += 1
            self._refuse(sender, f'it is malformed: {error}', _claims(msg.node, msg.pid))
            return
        why = self.check(hello, sender)
        if why is not None:
            self._refuse(sender, why, _claims(hello.node, hello.pid))
            return
        for gid in hello.gids:
            self._by_gid.pop(gid, None)  # re-inserted last: the oldest are forgotten first
            self._by_gid[gid] = hello
        while len(self._by_gid) > _KEPT:
            del self._by_gid[next(iter(self._by_gid))]

    def _refuse(self, sender: bytes, why: str, claims: str) -> None:
        """Count a refused hello; its sender is named by `_log_refusals` and `errors`."""
        now = time.monotonic()
        self.refused += 1
        refusal = self.refusals.get(sender)
        news = refusal is None or now - refusal.last >= ERROR_WINDOW_S
        if refusal is None:
            refusal = self.refusals[sender] = Refusal(sender, why, claims, first=now)
        refusal.why, refusal.claims = why, claims
        refusal.count += 1
        refusal.last = now
        self._log_refusals()
        if news:  # not yet an ERROR on /diagnostics: say it now
            self.urgent()

    def sender_name(self, sender: bytes) -> str:
        """The node the ROS graph names for publisher `sender` of zeus/pairing ('' unknown)."""
        for info in self._node.get_publishers_info_by_topic(self._sub.topic_name):
            if bytes(info.endpoint_gid)[:len(sender)] == sender:
                if info.node_name == _UNKNOWN_NODE:
                    return ''
                return info.node_namespace.rstrip('/') + '/' + info.node_name
        return ''

    def describe(self, refusal: Refusal) -> str:
        """`/node (gid <full hex>, its hello claims ...)`: the sender, as far as it is known."""
        if not refusal.name:
            refusal.name = self.sender_name(refusal.sender)
        claims = f', its hello claims to be {refusal.claims}' if refusal.claims else ''
        return (f'{refusal.name or "a node the graph has not named"} '
                f'(gid {refusal.sender.hex()}{claims})')

    def _log_refusals(self) -> None:
        """Name each refused sender: once the graph names it (or after _NAME_WAIT_S).

        Then one line per _REPEAT_S while it goes on: every refused hello is in a logged count,
        and a flood of them is not a flood of log lines.
        """
        now = time.monotonic()
        for refusal in self.refusals.values():
            if refusal.count == refusal.logged_count:
                continue
            if refusal.logged < 0:
                if not refusal.name:
                    refusal.name = self.sender_name(refusal.sender)
                if not refusal.name and now - refusal.first < _NAME_WAIT_S:
                    continue
            elif now - refusal.logged < _REPEAT_S:
                continue
            more = refusal.count - refusal.logged_count
            self._node.get_logger().error(
                f'refused {more} hello(s) on {self._sub.topic_name} from '
                f'{self.describe(refusal)}: {refusal.why}; no pairing reads it '
                f'({refusal.count} from this sender, {self.refused} in all; docs/security.md)')
            refusal.logged, refusal.logged_count = now, refusal.count

    def errors(self, window: float = ERROR_WINDOW_S) -> list[str]:
        """The /diagnostics ERROR line naming who sent the hellos refused lately (empty: none).

        A sender is named while its last refused hello is less than `window` seconds old.
        """
        now = time.monotonic()
        recent = [r for r in self.refusals.values() if now - r.last < window]
        if not recent:
            return []
        named = '; '.join(f'{self.describe(r)}: {r.why}' for r in recent)
        return [f'{sum(r.count for r in recent)} hello(s) on {self._sub.topic_name} refused '
                f'from {len(recent)} sender(s), in the last {window:g} s or before: {named}']

    def diagnostics_values(self) -> dict[str, Any]:
        """What every node with a handshake adds to its /diagnostics values."""
        return {'pairing': self.mode, 'hellos_refused': self.refused}

    def hello_of(self, gid: bytes) -> Hello | None:
        """The newest checked hello that lists publisher `gid` (None: none heard)."""
        return self._by_gid.get(gid.hex())

    def introduces(self, gid: bytes, node: str, agreed: Hello | None) -> str | None:
        """Why publisher `gid` of `node` may not replace the `agreed` peer (None: it may).

        It may when its own (checked) hello lists it under `node`, with a start nonce other
        than the agreed one, the agreed checkpoint sha256, and (with a key) a proof that
        checks.
        """
        hello = self.hello_of(gid)
        if agreed is None:
            return 'no hello of the paired node was heard at pairing, so no restart is believed'
        if hello is None:
            return 'it sent no valid hello (zeus/pairing) listing this publisher'
        if hello.node != node:
            return f'its hello names {hello.node}, the graph {node}'
        if hello.nonce == agreed.nonce:
            return 'its hello repeats the start nonce of the paired node (a replay)'
        if hello.sha256 != agreed.sha256:
            return (f'its checkpoint sha256 {hello.sha256 or "(none)"} is not the pair\'s '
                    f'{agreed.sha256 or "(none)"}')
        if not hello.verified(self.key):
            return f'its hello has no valid proof of the launch key (${KEY_ENV})'
        return None


def _claims(node: str, pid: int) -> str:
    """What a hello says of its sender, for the refusal line (unproven)."""
    return f'{node[:80] or "(no name)"}' + (f' pid {pid}' if pid else '')


def handshake_of(node: Node) -> Handshake:
    """The one Handshake of `node` (made on first use).

    Its hello subscription is a waitable, which rclpy's `destroy_node` leaves alone: the
    node's `destroy_node` is wrapped to free it first.
    """
    handshake = node.__dict__.get('_zeus_handshake')
    if handshake is None:
        handshake = node.__dict__['_zeus_handshake'] = Handshake(node)
        destroy_node = node.destroy_node

        def destroy() -> Any:
            handshake.destroy()
            return destroy_node()

        node.destroy_node = destroy  # type: ignore[method-assign]
    return handshake


def pairing_diagnostics(node: Node) -> tuple[dict[str, Any], list[str]]:
    """The pairing's /diagnostics values and ERROR lines of `node` (none without a handshake)."""
    handshake = node.__dict__.get('_zeus_handshake')
    if handshake is None:
        return {}, []
    return handshake.diagnostics_values(), handshake.errors()
