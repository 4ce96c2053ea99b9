"""The one place a node's /diagnostics array is built: its status, its peers, its hardware_id.

Why, by diagnostic_updater's and diagnostic_aggregator's conventions:
- `hardware_id` names the system and the device (`/r1/sim:Cheetah-Bias-v0`,
  `/robot:arm_reach`, `/r1/host:lab-pc`), fixed for the node's life, so two systems in one
  domain are told apart in rqt_robot_monitor and in an aggregator;
- a peer that went silent is a STALE status naming it (`/policy: peer /context_estimator`),
  OK again once it is heard: a node that stopped publishing would otherwise just disappear
  from the view of the nodes that depend on it;
- the message is never cut: it carries every line and its advice (`ros2 topic echo` shows
  128 characters of a string unless run with `--full-length`; a one-line summary is a display's
  business: `zeus inspect`).
"""

from __future__ import annotations

from collections.abc import Sequence
import socket
import time
from typing import TYPE_CHECKING, Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ['PEER_SILENT_S', 'PEER_STATUS', 'diagnostics_message', 'hardware_id',
           'peer_statuses', 'set_device', 'summary', 'unwatch_peers', 'watch_peer']

PEER_SILENT_S = 3.0
"""Seconds without a message from a peer that was heard before: its status turns STALE.
Above the lockstep loop's slowest cadence with a live peer missing (sim_bridge's default
action_timeout, 2 s, still steps on the safe action), so only a silent peer is called so."""
PEER_STATUS = ': peer '
"""What follows a node's name in its peer statuses (`/policy: peer /context_estimator`)."""
_DEVICE = '_zeus_hardware_device'
_HARDWARE_ID = '_zeus_hardware_id'
_WATCHED = '_zeus_watched_peers'


def set_device(node: Node, device: str) -> None:
    """Name the device a node stands for (`sim:<task>`, `robot:<task>`); default: the host."""
    node.__dict__[_DEVICE] = device


def hardware_id(node: Node) -> str:
    """`<namespace>/<device>`, computed once: stable for the node's life."""
    known = node.__dict__.get(_HARDWARE_ID)
    if known is None:
        device = node.__dict__.get(_DEVICE) or f'host:{socket.gethostname()}'
        known = f'{node.get_namespace().rstrip("/")}/{device}'
        node.__dict__[_HARDWARE_ID] = known
    return known


def watch_peer(node: Node, pairing: Any) -> None:
    """Report `pairing`'s paired publisher (senders.SenderPairing) as a peer of `node`."""
    node.__dict__.setdefault(_WATCHED, []).append(pairing)


def unwatch_peers(node: Node, pairings: Sequence[Any]) -> None:
    """Stop reporting `pairings` (a managed node's cleanup: its next configure pairs anew)."""
    watched = node.__dict__.get(_WATCHED, [])
    watched[:] = [p for p in watched if not any(p is gone for gone in pairings)]


def peer_statuses(node: Node, now: float | None = None) -> list[DiagnosticStatus]:
    """One status per peer heard so far: OK while it talks, STALE once silent PEER_SILENT_S.

    A peer heard on several topics (steps and observations) is one status; it is silent only
    when none of them has brought anything for that long.
    """
    now = time.monotonic() if now is None else now
    peers: dict[str, list[Any]] = {}
    for pairing in node.__dict__.get(_WATCHED, []):
        if pairing.paired is not None and pairing.last_message is not None:
            peers.setdefault(pairing.paired.node, []).append(pairing)
    statuses = []
    for peer, pairings in sorted(peers.items()):
        silent = now - max(p.last_message for p in pairings)
        what = ', '.join(dict.fromkeys(p.what for p in pairings))
        topics = ', '.join(dict.fromkeys(p.topic for p in pairings))
        status = DiagnosticStatus(name=f'{node.get_fully_qualified_name()}{PEER_STATUS}{peer}',
                                  hardware_id=hardware_id(node))
        if silent > PEER_SILENT_S:
            status.level = DiagnosticStatus.STALE
            status.message = (f'no {what} from {peer} on {topics} for {silent:.1f} s (heard '
                              f'before; STALE after {PEER_SILENT_S:g} s of silence): it stopped, '
                              'stalled or lost its connection; check its log and `ros2 node '
                              'list`')
        else:
            status.level = DiagnosticStatus.OK
            status.message = f'{what} from {peer}: last {silent:.1f} s ago'
        status.values = [KeyValue(key=key, value=str(value)) for key, value in (
            ('peer', peer), ('topics', topics), ('silent_s', f'{silent:.1f}'),
            ('stale_after_s', f'{PEER_SILENT_S:g}'))]
        statuses.append(status)
    return statuses


def diagnostics_message(
    node: Node, name: str, values: dict[str, object], problems: Sequence[str] = (),
    errors: Sequence[str] = (), peers: bool = True,
) -> DiagnosticArray:
    """The node's status `name` (ERROR / WARN / OK), then its peers' statuses (`peers`).

    ERROR with `errors`, WARN with `problems`, else OK; it comes first in the array, then one
    status per peer the node watches (peer_statuses), unless `peers` is False.

    `problems` are faults the node covers and counts; `errors` need someone to act. A node
    with a start handshake also reports its pairing mode ('keyed' / 'unkeyed'), the hellos it
    refused, and an ERROR naming their senders (handshake.py): the same in every node.
    """
    from zeus_ros.nodes.handshake import pairing_diagnostics

    pairing_values, pairing_errors = pairing_diagnostics(node)
    values = {**values, **pairing_values}
    errors = [*errors, *pairing_errors]
    status = DiagnosticStatus()
    status.name = f'{node.get_fully_qualified_name()}: {name}'
    status.hardware_id = hardware_id(node)
    status.level = (DiagnosticStatus.ERROR if errors else
                    DiagnosticStatus.WARN if problems else DiagnosticStatus.OK)
    status.message = '; '.join([*errors, *problems]) or 'ok'
    status.values = [KeyValue(key=key, value=str(value)) for key, value in values.items()]
    array = DiagnosticArray()
    array.header.stamp = node.get_clock().now().to_msg()
    array.status = [status, *(peer_statuses(node) if peers else [])]
    return array


def summary(message: str, width: int = 100) -> str:
    """A one-line summary of a status message for a terminal view (never for the message).

    Its first line whole when it fits, else cut at `width` with '...'; '(+N more)' when
    the message holds more lines ('; '-joined).
    """
    lines = message.split('; ')
    first = lines[0] if len(lines[0]) <= width else lines[0][:width - 3].rstrip() + '...'
    return first + (f' (+{len(lines) - 1} more)' if len(lines) > 1 else '')
