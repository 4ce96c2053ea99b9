"""zeus_ros.system.processes: the one way launch, demo and tests start and stop node processes."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from zeus_ros.system import processes

# A child that exits 0 on SIGINT unless told to ignore it (and/or SIGTERM), once ready.
CHILD = """
import signal, sys, time
signal.signal(signal.SIGINT, lambda *_: sys.exit(0))
for name in sys.argv[1:]:
    signal.signal(getattr(signal, name), signal.SIG_IGN)
print('ready', flush=True)
time.sleep(60)
"""

def _child(*ignored: str) -> subprocess.Popen[bytes]:
    process = processes.start_node([sys.executable, '-c', CHILD, *ignored],
                                   processes.ros_env(), stdout=subprocess.PIPE)
    assert process.stdout is not None and process.stdout.readline() == b'ready\n'
    return process


def test_stop_escalates_from_sigint_to_sigterm_to_sigkill() -> None:
    """Every child ends: on SIGINT if it takes it, else SIGTERM, else SIGKILL."""
    clean, deaf_to_int, deaf_to_both = _child(), _child('SIGINT'), _child('SIGINT', 'SIGTERM')
    processes.stop_nodes([clean, deaf_to_int, deaf_to_both], deadline=time.monotonic() + 0.5,
                         term_grace=0.5)
    assert clean.returncode == 0
    assert deaf_to_int.returncode == -signal.SIGTERM
    assert deaf_to_both.returncode == -signal.SIGKILL


def test_children_get_loopback_discovery_and_the_group_domain(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Given id > $ROS_DOMAIN_ID > a fresh one from $ZEUS_DOMAIN_RANGE; always LOCALHOST."""
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'SUBNET')
    monkeypatch.setenv('ROS_DOMAIN_ID', '42')
    assert processes.ros_env(7)['ROS_DOMAIN_ID'] == '7'
    env = processes.ros_env()
    assert env['ROS_DOMAIN_ID'] == '42' and env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    monkeypatch.delenv('ROS_DOMAIN_ID')
    monkeypatch.setenv(processes.DOMAIN_RANGE_ENV, '200-202')
    assert {int(processes.ros_env()['ROS_DOMAIN_ID']) for _ in range(30)} <= {200, 201, 202}
    monkeypatch.setenv(processes.DOMAIN_RANGE_ENV, '200-300')
    with pytest.raises(ValueError, match='ZEUS_DOMAIN_RANGE=200-300'):
        processes.fresh_domain_id()


def test_background_priority_is_batch_work_in_a_child() -> None:
    """SCHED_BATCH and the nice (also its session's, under autogroup) reach the process."""
    code = ('import os; from zeus_ros.system.processes import background_priority; '
            'print(background_priority(3, True)); '
            'print(os.sched_getscheduler(0) == os.SCHED_BATCH, os.nice(0))')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=60, start_new_session=True)
    applied, checked = done.stdout.splitlines()
    assert 'SCHED_BATCH' in applied and 'nice' in applied
    assert checked.split()[0] == 'True' and int(checked.split()[1]) >= 3
