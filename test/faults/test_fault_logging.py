"""Fault matrix, "logging never stops control": a recorder that cannot write, a killed policy.

The real group runs under `zeus launch --record`. The recorder's disk fills (a tmpfs filled by a
file where mounting is allowed, else the $ZEUS_WRITE_FAULT injection), then its writes are
denied (EACCES, through the injection: root ignores file modes): each time an ERROR, the loop
keeps stepping, a new bag once the fault clears. Then the policy is SIGKILLed: the launcher
restarts it after its back-off while sim_bridge applies the safe action. Every step is either
in a bag (after `zeus recover` of the dropped ones) or in the ranges the recorder names.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import signal
import subprocess
import sys
from typing import Any

import pytest
from small_disk import SmallDisk, mount_tmpfs

from zeus_ros.atomic_file import WRITE_FAULT_ENV

from live_fixtures import TASK, tiny_checkpoint
from ros_harness import (
    REPO,
    child_pids,
    driver_node,
    fresh_domain_id,
    read_until,
    ros_environment,
    spin_until,
    stop_launch,
)

pytestmark = pytest.mark.ros


def _params(tmp_path: Path, output: Path) -> Path:
    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    params = tmp_path / 'params.yaml'
    params.write_text(
        f'/**/sim_bridge:\n  ros__parameters:\n    task: {TASK}\n    log_every: 100\n'
        '    action_timeout: 0.5\n'
        + ''.join(f'/**/{name}:\n  ros__parameters:\n    checkpoint: {checkpoint}\n'
                  f'    task: {TASK}\n' for name in ('context_estimator', 'policy'))
        + f'/**/recorder:\n  ros__parameters:\n    output: {output}\n'
        '    flush_period_s: 0.2\n    retry_s: 0.3\n    retry_max_s: 1.0\n'
        '/**/zeus_launch:\n  ros__parameters:\n    respawn:\n'
        '      policy: {limit: 2, window_s: 60.0, backoff_s: 0.5}\n')
    return params


def _steps(bag: Path) -> list[int]:
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == '/zeus/step']
        return [int(reader.deserialize(raw, c.msgtype).step)
                for c, _, raw in reader.messages(connections=conns)]


def _child(parent: int, module: str) -> int:
    for pid, argv in child_pids(parent).items():
        if module.encode() in argv:
            return pid
    raise AssertionError(f'no child of {parent} runs {module}')


def test_a_recorder_that_cannot_write_and_a_killed_policy_never_stop_the_loop(
        tmp_path: Path) -> None:
    """Disk full, then permission denied, then policy SIGKILL: the loop steps on; exit 3."""
    root = tmp_path / 'disk'
    root.mkdir()
    switch = tmp_path / 'write_fault'
    disk = SmallDisk(root, mount_tmpfs(root, '64m'), switch)
    out = root / 'bag'
    domain = fresh_domain_id()
    env = ros_environment(domain) | {WRITE_FAULT_ENV: str(switch)}
    with driver_node(domain) as probe:
        _run(probe, env, tmp_path, disk, out)


def _run(probe: Any, env: dict[str, str], tmp_path: Path, disk: SmallDisk, out: Path) -> None:
    """The group under zeus launch through the faults; `probe` watches /diagnostics."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    recorder: dict[str, Any] = {}
    probe.create_subscription(DiagnosticArray, '/diagnostics', lambda msg: recorder.update(
        {s.name.rsplit(':', 1)[-1].strip(): s for s in msg.status
         if s.name.startswith('/recorder')}), 10)
    root, switch = disk.root, disk.switch
    launch = subprocess.Popen(
        [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params', str(_params(tmp_path, out)),
         '--record', '--no-progress'], cwd=REPO, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, start_new_session=True)
    lines: list[str] = []
    try:
        read_until(launch, 'step 200 ', lines)
        disk.fill()
        read_until(launch, 'cannot write', lines)
        assert spin_until(probe, lambda: 'bag' in recorder and recorder['bag'].level ==
                          DiagnosticStatus.ERROR, 10), recorder
        assert 'cannot write bags' in recorder['bag'].message, recorder['bag'].message
        for _ in range(2):  # the loop keeps stepping while nothing can be written
            read_until(launch, 'sim_bridge]: step ', lines)
        disk.free()
        read_until(launch, 'recording again into', lines)
        assert spin_until(probe, lambda: recorder['bag'].level == DiagnosticStatus.OK, 10), \
            recorder['bag'].message  # the ERROR clears with its cause; the count stays
        read_until(launch, 'sim_bridge]: step ', lines)  # the new bag holds steps
        switch.write_text('EACCES')
        read_until(launch, 'Permission denied', lines)
        read_until(launch, 'sim_bridge]: step ', lines)
        switch.unlink()
        read_until(launch, 'recording again into', lines)
        os.kill(_child(launch.pid, 'zeus_ros.nodes.policy_node'), signal.SIGKILL)
        read_until(launch, 'policy died with exit code -9; the loop keeps running on the safe '
                   'action; restarting it in 0.5 s', lines)
        read_until(launch, 'restarted', lines)  # sim_bridge re-pairs with the new policy
        read_until(launch, 'sim_bridge]: step ', lines)
        launch.send_signal(signal.SIGINT)
        rest = launch.communicate(timeout=60)[0]
    except BaseException:
        if disk.mounted:
            subprocess.run(['umount', '-l', str(root)], check=False)
        raise
    finally:
        stop_launch(launch)
    try:
        _check(''.join(lines) + rest, launch.returncode, out, disk)
    finally:
        if disk.mounted:
            subprocess.run(['umount', '-l', str(root)], check=False)


def _check(output: str, code: int, out: Path, disk: SmallDisk) -> None:
    """Exit 3, the gap and the restart named; every step in a bag or in the named ranges."""
    from zeus_ros.cli import recover

    assert code == 3, output[-3000:]
    assert 'Traceback' not in output, output[output.find('Traceback') - 2000:][:4000]
    assert 'timeout' in output  # the safe action while the policy was away
    gap = re.search(r'the recording has 1 gap\(s\): recorder could not write (\d+) steps '
                    r'\(([\d, -]+)\)', output)
    assert gap, output[-3000:]
    assert '1 restart(s): policy died at' in output, output[-3000:]
    last = int(re.findall(r'stopped after step (\d+)', output)[-1])

    bags = sorted(p for p in out.iterdir() if p.is_dir())
    assert len(bags) == 3, bags  # the first two were dropped by a fault, the third closed
    for bag in bags[:2]:
        assert recover.main([str(bag)]) == 0
    recorded = {step for bag in bags for step in _steps(bag)}
    named = set()
    for part in gap.group(2).split(', '):
        first, _, end = part.partition('-')
        named |= set(range(int(first), int(end or first) + 1))
    assert len(named) == int(gap.group(1))
    missing = set(range(last + 1)) - recorded - named
    assert not missing, sorted(missing)[:20]
    print(f'recorder disk full + EACCES, policy SIGKILL ({disk.how}): {len(recorded)} steps '
          f'recorded, {len(named)} named unrecorded ({gap.group(2)}), loop to step {last}')
