"""robot_bridge's camera path: the zoo's pixel checkpoint drives a fake robot cheetah.

Real processes on a loopback-only domain: test/fake_cheetah.py (Cheetah-Motor-v0's physics and
camera behind JointState, an Image topic and a forward command controller in another joint
order) and the product's launcher, `zeus launch --robot --obs pixels --record` (robot_bridge,
context_estimator and policy with the task's zoo pixel checkpoint, and the recorder: the group
waits for it, so its bag holds every step from step 0).
"""

from __future__ import annotations

import json
from pathlib import Path
import re
import sys
from typing import Any

import numpy as np
import pytest
import yaml

from zeus_ros.nodes.messages import stamp_ns

from fake_cheetah import CheetahPlant
from ros_harness import REPO, ProcessGroup, driver_node, python_module, spin_until

pytestmark = [pytest.mark.ros, pytest.mark.slow]
PARAMS = REPO / 'test' / 'fake_cheetah.yaml'
STEPS = 60
ACTION_TO_CONTROLLER = [5, 4, 3, 2, 1, 0]
"""action order (bthigh ... ffoot) -> the controller's (ffoot ... bthigh)."""
MIN_LEAD_M = 1.0
"""How much farther than zero commands the checkpoint must drive the cheetah in STEPS steps.
Measured here (2 cores shared with two trainings, 5 Hz): 2.3-4.3 m (zero commands: 0.00 m)."""


def read_bag(bag: Path) -> tuple[dict[str, dict[int, Any]], set[int]]:
    """Messages of the step topics by step index, and the stamps of the recorded frames."""
    from rosbags.highlevel import AnyReader

    by_step: dict[str, dict[int, Any]] = {}
    frames = set()
    with AnyReader(sorted(path.parent for path in bag.rglob('metadata.yaml'))) as reader:
        for connection, _t, raw in reader.messages():
            msg: Any = reader.deserialize(raw, connection.msgtype)
            if connection.topic == '/zeus/observation/image':  # Image.step: its row length
                frames.add(stamp_ns(msg.header.stamp))
            elif hasattr(msg, 'step'):
                by_step.setdefault(connection.topic, {})[msg.step] = msg
    return by_step, frames


def test_the_zoo_pixel_checkpoint_drives_a_robot_through_the_camera_path(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """Every step's frame reaches the policy, its commands the plant; the cheetah runs."""
    from diagnostic_msgs.msg import DiagnosticArray

    params = yaml.safe_load(PARAMS.read_text())
    params['/**/robot_bridge']['ros__parameters']['max_steps'] = STEPS
    params['/**/recorder'] = {'ros__parameters': {'output': str(tmp_path / 'bag')}}
    (tmp_path / 'cheetah.yaml').write_text(yaml.safe_dump(params))
    out = tmp_path / 'cheetah.json'
    fake = ros_processes.start('fake_cheetah', [sys.executable,
                                                str(REPO / 'test' / 'fake_cheetah.py'), str(out)])
    ros_processes.wait_for_log('fake_cheetah', 'fake cheetah up')
    diagnostics: dict[str, dict[str, str]] = {}
    with driver_node(ros_processes.domain_id, 'camera_test') as driver:
        driver.create_subscription(DiagnosticArray, '/diagnostics', lambda m: diagnostics.update(
            {s.name: {kv.key: kv.value for kv in s.values} for s in m.status}), 10)
        launch = ros_processes.start('launch_cheetah', python_module(
            'zeus_ros.cli', 'launch', '--robot', '--params', str(tmp_path / 'cheetah.yaml'),
            '--obs', 'pixels', '--record', '--no-progress', '--timeout', '120'))
        assert spin_until(driver, lambda: launch.poll() is not None, 150)
    log = ros_processes.log_text('launch_cheetah')
    assert launch.returncode == 0 and "node 'robot_bridge' finished" in log, log[-3000:]
    assert 'cheetah_motor_v0/pixels_student.pt' in log
    ros_processes.stop(fake)
    plant = json.loads(out.read_text())
    topics, frames = read_bag(tmp_path / 'bag')

    # Every step's frame reached the policy: the frame went out with the step's stamp, and the
    # policy's action answers the step with that stamp (a pixel policy acts on a step only once
    # the frame of its stamp arrived); no input or frame was rejected on the way.
    feedback, actions = topics['/zeus/step'], topics['/zeus/action']
    assert sorted(feedback) == list(range(STEPS + 1))
    stamps = {step: stamp_ns(msg.header.stamp) for step, msg in feedback.items()}
    assert set(stamps.values()) <= frames, 'a step went out without its frame'
    assert all(stamp_ns(actions[step].header.stamp) == stamps[step] for step in stamps)
    counts = re.search(r'max_steps=\d+ reached; counts (\{.*\})', log)
    assert counts, log[-3000:]
    bridge = yaml.safe_load(counts.group(1))
    assert bridge['rejected_inputs'] == bridge['rejected'] == 0, bridge
    assert not re.search(r'rejected \S+ for step', log), 'the estimator or policy rejected input'

    # The commands reached the plant in the controller's order.
    sent = {tuple(np.round(np.clip(np.asarray(a.data, np.float64), -1, 1)
                           [ACTION_TO_CONTROLLER], 6)) for a in actions.values()}
    received = [tuple(np.round(c, 6)) for c in plant['commands']]
    policy_commands = [c for c in received if any(c)]  # all zeros: the safe command
    assert set(policy_commands) <= sent, 'a command reached the robot in the wrong order'
    assert len(set(policy_commands)) >= 0.9 * len(sent), 'actions were lost on the way'

    # The checkpoint drives the cheetah forward, clearly farther than zero commands would.
    rootx = plant['rootx']
    ticks = min(STEPS, len(rootx) - 1)
    zero = CheetahPlant()
    assert rootx[0] == pytest.approx(zero.rootx)  # the same start (seed 0, switched on at 0)
    for _ in range(ticks):
        zero.step({})
    driven, still = rootx[ticks] - rootx[0], zero.rootx - rootx[0]
    latency = next((v for n, v in diagnostics.items() if 'robot_bridge' in n), {})
    print(f'{ticks} ticks: driven {driven:.2f} m, zero commands {still:.2f} m; observation -> '
          f'action p50 {latency.get("latency_p50_ms_run")} ms, p99 '
          f'{latency.get("latency_p99_ms_run")} ms (run, robot_bridge /diagnostics)')
    assert driven - still > MIN_LEAD_M, (driven, still)
