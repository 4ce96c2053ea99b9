"""Loopback really means loopback: the running nodes' RTPS ports listen on 127.0.0.1 only.

ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST keeps discovery local, but with Fast DDS's default
transports every participant still listens on 0.0.0.0. The package's profile
(params/dds/fastdds_loopback.xml, set by scripts/env.sh and every launcher) binds them to
loopback. The sockets are read from /proc, as `ss -uanp` lists them.
"""

from __future__ import annotations

from pathlib import Path
import socket
import struct
import subprocess
import sys

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
