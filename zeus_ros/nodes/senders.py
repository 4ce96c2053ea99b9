"""Who sent a message: a subscription that sees each message's publisher, and a pairing.

A robot must be driven by its own policy only. DDS lets any process on the domain publish on
`zeus/action`, and the message itself says nothing about who sent it; the publisher's GID
(`rmw_message_info_t.publisher_gid`) does. rclpy in Jazzy does not hand that field to Python
(rclpy#1466 adds it in later releases), so `SenderSubscription` takes each message through
rcl's serialized take with ctypes, which fills the whole message info, and deserializes it with
rclpy. `SenderPairing` then pairs the topic with one publisher of the ROS graph (a configured
node, or the only publisher at start-up), refuses and counts everything else, and names every
other publisher once. A paired node that restarts (a new GID, the same name) is followed only
through the explicit handshake of handshake.py (a new start nonce, the same checkpoint, the
launch key's proof), never by its name alone.

This is a guard against mistakes and stray processes, not access control: without a launch
key ('unkeyed'), a process running our own node code under the paired node's name after it
died is believed; a stalled paired node (its publisher still in the graph) is never replaced
without a key, whatever the newcomer's hello says. The real answer is SROS2 (enclaves and a
permissions file that lets only the policy publish `zeus/action`): docs/security.md.
"""

from __future__ import annotations

from dataclasses import dataclass
import time
from typing import TYPE_CHECKING

from zeus_ros.nodes.diagnostics import watch_peer
from zeus_ros.nodes.handshake import Hello, handshake_of
from zeus_ros.nodes.rcl_bindings import GID_SIZE
from zeus_ros.nodes.sender_subscription import SenderSubscription

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ['INTRODUCTION_S', 'PAIRING_SETTLE_S', 'Sender', 'SenderPairing', 'SenderSubscription']

PAIRING_SETTLE_S = 2.0
"""Seconds the action publishers must stay the same before a bridge with no `action_sender`
pairs with the only one. Discovery names endpoints one participant at a time: with 0.5 s a
bridge started beside two action publishers paired with the first in 4 of 10 runs (the second
was discovered 0.5-1 s later). Launches set `action_sender` and never wait for this."""
INTRODUCTION_S = 3.0
"""Seconds a newcomer under the paired node's name has to complete the handshake (its hello
may come after its first messages) before it is named as an impostor."""
_UNKNOWN_NODE = '_NODE_NAME_UNKNOWN_'  # rmw_dds_common's name before the node is announced


@dataclass(frozen=True)
class Sender:
    """One publisher in the ROS graph: its GID and its node's fully qualified name."""

    gid: bytes
    node: str  # '' while the graph knows the endpoint but not yet its node

    def __str__(self) -> str:
        # The whole GID: its last 8 hex digits (the entity id) are the same in every process.
        return f'{self.node or "a node not yet named"} (gid {self.gid.hex()})'


class SenderPairing:
    """Which publisher of a topic may drive this node; counts and names everyone else.

    `expected` ('' or a fully qualified node name such as /r1/policy) says whom to pair with;
    empty means the node `follow` (another pairing of this node, e.g. the steps for the
    observations) paired with, else the only publisher on the topic when `pair()` is called
    (start-up); `setting` names the parameter that sets it, for messages ('' when the node
    has none). The pair is agreed by publisher GID and node name, and with the hello the node
    sent at its start (handshake.py). A paired node that restarts publishes under a new GID:
    its new publisher (same node name) is paired only when its hello passes
    `Handshake.introduces`, and once the old one has left the graph or, with the launch key
    only, has been silent for `takeover_after` seconds (a killed process stays in the graph
    until its DDS lease ends, 20 s with Fast DDS's defaults). Unkeyed, a newcomer under the
    paired name waits, named once as a WARN, until the old publisher has left the graph: a
    stalled paired node is never replaced by whoever sends a hello. Everything else is
    refused (`refused` counts it) and named once.
    """

    def __init__(self, node: Node, topic: str, expected: str = '', what: str = 'messages',
                 takeover_after: float = 1.0, setting: str = 'action_sender',
                 follow: SenderPairing | None = None) -> None:
        self._node = node
        self.topic = topic
        self._expected = expected
        self.follow = follow
        self.what = what
        self.setting = setting
        self.paired: Sender | None = None
        self._refused = 0
        self._early: dict[bytes, int] = {}  # a possible restart's messages before its hello
        self.before_hello = 0
        """Messages of a restart refused before its hello was checked: its own, not foreign."""
        self.takeover_after = takeover_after
        self._handshake = handshake_of(node)
        self._agreed: Hello | None = None  # the paired node's hello (its start nonce)
        self._heard = time.monotonic()
        self.last_message: float | None = None
        """When the paired publisher's last message was accepted (monotonic; None: not yet)."""
        watch_peer(node, self)  # its silence is a STALE peer status (diagnostics.py)
        self._retired: set[bytes] = set()  # earlier paired publishers (a restarted node's)
        self._graph: dict[bytes, Sender] = {}
        self._graph_at = -1.0
        self._named: set[bytes] = set()
        self._newcomers: dict[bytes, float] = {}  # same-name GIDs: first seen (monotonic)
        self._waiting: set[bytes] = set()  # unkeyed newcomers named as waiting (WARN, once)
        self._settling: tuple[frozenset[bytes], float] = (frozenset(), 0.0)

    @property
    def refused(self) -> int:
        """Messages refused from publishers other than the pair (`foreign` in /diagnostics).

        A restart's messages that came before its hello was checked count only once its
        introduction has failed (INTRODUCTION_S after it was first seen); those of the restart
        that did pair are `before_hello`.
        """
        return self._refused + sum(count for gid, count in self._early.items()
                                   if self._late(gid))

    def _late(self, gid: bytes) -> bool:
        """A possible restart first seen INTRODUCTION_S ago or more (its grace is over)."""
        return time.monotonic() - self._newcomers.get(gid, -INTRODUCTION_S) >= INTRODUCTION_S

    @property
    def expected(self) -> str:
        """The node to pair with: the configured one, else the followed pairing's node."""
        if self._expected:
            return self._expected
        if self.follow is not None and self.follow.paired is not None:
            return self.follow.paired.node
        return ''

    def agreed(self) -> Hello | None:
        """The hello of the paired node (its newest: a live redeploy updates its sha256).

        Only a checked hello (handshake.py: sent by the paired node's own process, with the
        key's proof where there is a key) is ever read here, and once agreed, only one of
        the same start (nonce) updates it.
        """
        if self.paired is not None:
            hello = self._handshake.hello_of(self.paired.gid)
            if hello is not None and hello.node == self.paired.node and (
                    self._agreed is None or hello.nonce == self._agreed.nonce):
                self._agreed = hello
        return self._agreed

    def publishers(self, max_age: float = 0.0) -> dict[bytes, Sender]:
        """The topic's publishers from the graph, re-read when older than `max_age` seconds."""
        now = time.monotonic()
        if now - self._graph_at > max_age:
            self._graph = {}
            for info in self._node.get_publishers_info_by_topic(self.topic):
                name = '' if info.node_name == _UNKNOWN_NODE else \
                    info.node_namespace.rstrip('/') + '/' + info.node_name
                gid = bytes(info.endpoint_gid)[:GID_SIZE]
                self._graph[gid] = Sender(gid, name)
            self._graph_at = now
        return self._graph

    def pair(self, settle: float = 0.0) -> str | None:
        """Pair with the expected node's publisher or the only one; else say what is wrong.

        `settle` (seconds, used at start-up when no node is expected): pair with the only
        publisher only once the set of publishers has stayed the same that long. Discovery
        reports the endpoints of a graph one by one, so "the only one" seen at the first
        instant may be the first of two.
        """
        graph = list(self.publishers().values())
        candidates = [s for s in graph if s.node == self.expected] if self.expected else graph
        wanted = self.expected or 'a publisher'
        if not candidates:
            return f'{wanted} on {self.topic}' + (
                f' ({self.setting}; found {", ".join(map(str, graph))})' if graph else '')
        if not self.expected and settle > 0:
            seen, now = frozenset(s.gid for s in graph), time.monotonic()
            if seen != self._settling[0]:
                self._settling = (seen, now)
            if now - self._settling[1] < settle:
                return f'the publishers of {self.topic} to settle ({len(graph)} so far)'
        if any(not s.node for s in candidates):
            return f'the ROS graph to name the publishers of {self.topic}'
        if len(candidates) > 1:
            return (f'one publisher on {self.topic}, found {len(candidates)}: '
                    f'{", ".join(map(str, candidates))}; stop the extra ones' + (
                        f' or set {self.setting} to the node to follow' if self.setting
                        else ''))
        self.paired = candidates[0]
        self._agreed = None
        self._heard = time.monotonic()
        self._node.get_logger().info(
            f'paired with {self.paired} on {self.topic}: only its {self.what} are applied')
        return None

    def accepts(self, gid: bytes) -> bool:
        """True for the paired publisher (re-pairing after a restart); else count and name."""
        if self.paired is not None and gid == self.paired.gid:
            self._heard = self.last_message = time.monotonic()
            return True
        graph = self.publishers(max_age=0.1)
        if gid not in graph:
            graph = self.publishers(max_age=0.02)  # a newcomer: the graph may just be late
        sender = graph.get(gid)
        old = self.paired  # before _may_take_over: its pair() sets self.paired on first contact
        if sender is not None and self._may_take_over(sender, graph):
            self.paired = sender
            self._heard = self.last_message = time.monotonic()
            early = self._early.pop(sender.gid, 0)
            if self._late(sender.gid):  # already counted as refused (`refused`): stays so
                self._refused += early
            else:
                self.before_hello += early
            if old is not None:
                self._retired.add(old.gid)
                self._agreed = self._handshake.hello_of(sender.gid)
                how = ("the launch key's proof" if self._handshake.key else
                       f'unkeyed: its old publisher (gid {old.gid.hex()}) left the graph')
                self._node.get_logger().warning(
                    f'{sender} now drives {self.topic}: {old.node} restarted (handshake: new '
                    f'start nonce, checkpoint sha256 {self._agreed.sha256 or "(none)"}, '
                    f'pid {self._agreed.pid or "?"}, {how})'
                    if self._agreed is not None else f'{sender} now drives {self.topic}')
            return True
        if sender is None or not sender.node or self._within_introduction(sender, graph):
            # Foreign only if it turns out not to be the restart (see `refused`). A publisher
            # the graph has not named yet may be the restart too (the graph learns a node's
            # name after its endpoints: 10 of a restart's actions under load): the same grace.
            self._newcomers.setdefault(gid, time.monotonic())
            self._early[gid] = self._early.get(gid, 0) + 1
        else:
            self._refused += 1 + self._early.pop(sender.gid, 0)
        if sender is not None and not self._introducing(sender, graph):
            self._name_once(sender, graph)
            return False
        if sender is not None and sender.node and sender.gid not in self._waiting and \
                self._restart_state(sender, graph) == 'waiting':
            self._waiting.add(sender.gid)
            self._node.get_logger().warning(
                f'{sender} under the paired name waits to drive {self.topic}: unkeyed, a '
                f'restart is believed only once the paired publisher (gid '
                f'{self.paired.gid.hex() if self.paired else "?"}) has left the ROS graph '
                '(a killed process: its DDS lease, ~20 s); set $ZEUS_PAIRING_KEY to re-pair '
                'at once by proof (docs/security.md)')
        return False

    def _may_take_over(self, sender: Sender, graph: dict[bytes, Sender]) -> bool:
        """The paired node restarted (its old publisher is gone), or nothing is paired yet."""
        if self.paired is None:
            return self.pair() is None and self.paired is not None and \
                self.paired.gid == sender.gid
        return self._successor(sender, graph)

    def _successor(self, sender: Sender, graph: dict[bytes, Sender]) -> bool:
        """The paired node under a new GID, its old one gone (or keyed: silent), introduced."""
        if self._restart_state(sender, graph) != 'possible':
            return False
        return self._handshake.introduces(sender.gid, sender.node, self.agreed()) is None

    def _restart_state(self, sender: Sender, graph: dict[bytes, Sender]) -> str:
        """Whether `sender` may be the paired node's restart: 'possible', 'waiting' or 'no'.

        'possible': same name as the paired node, which is gone (or, keyed, silent);
        'waiting': so, but unkeyed and the paired publisher is silent and still in the graph;
        'no': anything else. Beside a paired node that talks, a same-name publisher is a
        second publisher at once. Unkeyed, a hello proves nothing an impostor could not
        write, so a stalled paired node stays paired until its publisher leaves the graph.
        A possible restart's handshake grace (INTRODUCTION_S) starts when it is first seen
        so.
        """
        if self.paired is None or sender.node != self.paired.node or \
                sender.gid in self._retired:
            return 'no'
        if self.paired.gid in graph:
            if time.monotonic() - self._heard < self.takeover_after:
                return 'no'
            if not self._handshake.key:
                return 'waiting'
        self._newcomers.setdefault(sender.gid, time.monotonic())
        return 'possible'

    def _introducing(self, sender: Sender, graph: dict[bytes, Sender]) -> bool:
        """A restart that may still introduce itself: not named as a second publisher yet.

        That is one within INTRODUCTION_S of its handshake, or (unkeyed) one waiting for the
        paired publisher to leave the graph.
        """
        return self._within_introduction(sender, graph) or \
            self._restart_state(sender, graph) == 'waiting'

    def others(self) -> list[Sender]:
        """Publishers on the topic besides the paired one (each is named once in the log)."""
        graph = self.publishers(max_age=0.5)
        if self.paired is None:  # one publisher is the one to pair with; more are ambiguous
            return list(graph.values()) if len(graph) > 1 else []
        found = [s for gid, s in graph.items() if gid not in self._retired
                 and gid != self.paired.gid and not self._within_introduction(s, graph)]
        for sender in found:
            if self._restart_state(sender, graph) != 'waiting':  # that one had its WARN line
                self._name_once(sender, graph)
        return found

    def _within_introduction(self, sender: Sender, graph: dict[bytes, Sender]) -> bool:
        """A possible restart still inside its INTRODUCTION_S: not yet an ERROR anywhere.

        Unlike `_introducing`, an unkeyed newcomer waiting for the paired publisher to leave
        the graph is not spared /diagnostics: its messages are refused meanwhile, whoever it
        is (a stall impostor or a restart waiting out the DDS lease), and the operator sees it
        at the next status, not only once the paired node talks again.
        """
        state = self._restart_state(sender, graph)
        return state == 'possible' and \
            time.monotonic() - self._newcomers[sender.gid] < INTRODUCTION_S

    def errors(self) -> list[str]:
        """The /diagnostics ERROR line while other publishers exist (empty: none)."""
        others = self.others()
        if not others:
            return []
        named = ', '.join(f'{s}' + (f' [same name as the paired node: {why}]'
                                    if (why := self._why_refused(s, self._graph)) else '')
                          for s in others)
        return [f'{len(others)} other publisher(s) on {self.topic}: {named}; their '
                f'{self.what} are refused']

    def _why_refused(self, sender: Sender, graph: dict[bytes, Sender]) -> str:
        """Why a publisher under the paired node's name is not its restart ('' otherwise)."""
        if self.paired is None or sender.node != self.paired.node:
            return ''
        state = self._restart_state(sender, graph)
        if state == 'no':
            return 'the paired publisher is alive'
        if state == 'waiting':
            return 'unkeyed: the paired publisher is still in the graph'
        why = self._handshake.introduces(sender.gid, sender.node, self.agreed())
        return why or 'its restart is pending its first message'

    def _name_once(self, sender: Sender, graph: dict[bytes, Sender]) -> None:
        if sender.gid in self._named or not sender.node:  # named once the graph knows it
            return
        self._named.add(sender.gid)
        paired = self.paired or self.expected or 'nobody yet'
        why = self._why_refused(sender, graph)
        self._node.get_logger().error(
            f'a second publisher on {self.topic}: {sender}; its {self.what} are refused '
            f'(paired with {paired})' + (f'; under the paired name but {why}' if why else '')
            + '. Use SROS2 to keep it off the domain (docs/security.md)')
        self._handshake.urgent()  # its ERROR on /diagnostics now, not at the next tick
