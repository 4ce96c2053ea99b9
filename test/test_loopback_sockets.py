"""Loopback really means loopback: the running nodes' RTPS ports listen on 127.0.0.1 only.

ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST keeps discovery local, but with Fast DDS's default
transports every participant still listens on 0.0.0.0. The package's profile
(params/dds/fastdds_loopback.xml, set by scripts/env.sh and every launcher) binds them to
loopback. The sockets are read from /proc, as `ss -uanp` lists them. Left off loopback under
LOCALHOST: two Fast DDS send sockets per participant that nothing reads (docs/security.md).
"""

from __future__ import annotations

from pathlib import Path
import socket
import struct
import subprocess
import sys
import time

import pytest

from ros_harness import child_pids, fresh_domain_id, read_until, ros_environment, stop_launch

pytestmark = pytest.mark.ros


def udp_sockets(pid: int) -> list[tuple[str, int]]:
    """(address, port) of every IPv4/IPv6 UDP socket process `pid` holds."""
    inodes = set()
    for fd in Path(f'/proc/{pid}/fd').iterdir():
        try:
            target = fd.readlink().name
        except OSError:
            continue
        if target.startswith('socket:['):
            inodes.add(target[len('socket:['):-1])
    found = []
    for table, family in (('udp', socket.AF_INET), ('udp6', socket.AF_INET6)):
        for line in Path(f'/proc/{pid}/net/{table}').read_text().splitlines()[1:]:
            fields = line.split()
            if fields[9] not in inodes:
                continue
            address, port = fields[1].split(':')
            raw = bytes.fromhex(address)
            if family == socket.AF_INET:
                text = socket.inet_ntop(family, struct.pack('<I', int(address, 16)))
            else:
                words = struct.unpack('<4I', raw)
                text = socket.inet_ntop(family, struct.pack('>4I', *words))
            found.append((text, int(port, 16)))
    return found


def test_every_rtps_port_of_the_running_nodes_listens_on_loopback_only() -> None:
    """sim_bridge, estimator and policy under `zeus launch`: their domain's RTPS ports.

    The domain's well-known ports (7400 + 250 * domain + 0..249: discovery and user traffic,
    unicast and multicast) are bound to 127.0.0.1, none to 0.0.0.0 or another interface.
    """
    domain = fresh_domain_id()
    env = ros_environment(domain)
    assert env['FASTRTPS_DEFAULT_PROFILES_FILE'].endswith('params/dds/fastdds_loopback.xml')
    launch = subprocess.Popen(
        [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--timeout', '60', '--no-progress'],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    try:
        read_until(launch, 'paired with /context_estimator', lines)
        nodes = child_pids(launch.pid)
        assert len(nodes) == 3, nodes
        base = 7400 + 250 * domain
        rtps = {pid: [(a, p) for a, p in udp_sockets(pid) if base <= p < base + 250]
                for pid in nodes}
    finally:
        stop_launch(launch)
    for pid, sockets in rtps.items():
        assert sockets, (pid, nodes[pid])  # each node is a participant of the domain
        assert all(address == '127.0.0.1' for address, _ in sockets), (nodes[pid], sockets)


def _udp_rows(pid: int) -> dict[tuple[str, int], int]:
    """(address, port) -> bytes queued unread, for process `pid`'s IPv4 UDP sockets."""
    inodes = set()
    for fd in Path(f'/proc/{pid}/fd').iterdir():
        try:
            target = fd.readlink().name
        except OSError:
            continue
        if target.startswith('socket:['):
            inodes.add(target[len('socket:['):-1])
    rows = {}
    for line in Path(f'/proc/{pid}/net/udp').read_text().splitlines()[1:]:
        fields = line.split()
        if fields[9] in inodes:
            address, port = fields[1].split(':')
            text = socket.inet_ntop(socket.AF_INET, struct.pack('<I', int(address, 16)))
            rows[(text, int(port, 16))] = int(fields[4].split(':')[1], 16)
    return rows


NODE = ('import rclpy, time\n'
        'rclpy.init()\n'
        'node = rclpy.create_node("loopback_probe")\n'
        'print("up", flush=True)\n'
        'time.sleep(60)\n')


def test_the_two_off_loopback_sockets_are_send_only_and_never_read() -> None:
    """What is left off loopback: Fast DDS's two UDP *send* sockets, which nothing reads.

    Under LOCALHOST every participant holds, besides its 127.0.0.1 sockets, one UDP socket on
    0.0.0.0 and one per other interface address, on ephemeral ports outside the domain's RTPS
    range (UDPTransportInterface::OpenOutputChannel of a transport with no white-list; strace in
    docs/security.md). They are output sockets: no receive thread reads them, so a datagram that
    reaches one is queued by the kernel and never parsed. Measured here over loopback only
    (3 datagrams to the 0.0.0.0 one stay queued, unread, 3 s later); nothing is sent to any
    other address.
    """
    domain = fresh_domain_id()
    env = ros_environment(domain)
    node = subprocess.Popen([sys.executable, '-c', NODE], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        assert node.stdout is not None
        assert node.stdout.readline().strip() == 'up'
        time.sleep(1.0)
        rows = _udp_rows(node.pid)
        base = 7400 + 250 * domain
        off = [(a, p) for a, p in rows if a != '127.0.0.1']
        assert len(off) <= 2, rows  # 0.0.0.0 and the machine's address, nothing else
        assert all(not base <= p < base + 250 for _, p in off), rows
        any_ports = [p for a, p in off if a == '0.0.0.0']
        assert len(any_ports) <= 1, rows
        if any_ports:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                for _ in range(3):
                    probe.sendto(b'RTPS\x02\x02\x01\x0fzeus-probe', ('127.0.0.1', any_ports[0]))
            time.sleep(3.0)
            queued = _udp_rows(node.pid)[('0.0.0.0', any_ports[0])]
            assert queued > 0, rows  # still in the kernel's queue: the process never reads it
    finally:
        node.kill()
        node.wait(timeout=30)
