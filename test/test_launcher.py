"""`zeus launch`: one domain for the group, prefixed logs, everything stops when one node dies."""

from __future__ import annotations

import subprocess
import sys

import pytest

from ros_harness import REPO, fresh_domain_id, ros_environment

pytestmark = pytest.mark.ros


def test_a_dying_node_stops_the_group_and_is_named(tmp_path) -> None:
    """A policy with a missing checkpoint exits 2; launch stops sim_bridge and names the policy."""
    params = tmp_path / 'params.yaml'
    params.write_text(
        'sim_bridge:\n  ros__parameters:\n    task: Cheetah-Run-v0\n'
        'policy:\n  ros__parameters:\n'
        f'    checkpoint: {tmp_path / "missing.pt"}\n')
    result = subprocess.run(
        [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params', str(params),
         '--nodes', 'sim_bridge,policy', '--timeout', '120'],
        cwd=REPO, env=ros_environment(fresh_domain_id()), capture_output=True, text=True,
        timeout=180, check=False)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "node 'policy' died with exit code 2" in result.stderr
    assert '[policy] error: policy:' in result.stdout and 'missing.pt' in result.stdout
    assert '[sim_bridge]' in result.stdout


def test_the_group_runs_until_the_time_limit_then_stops_cleanly(tmp_path) -> None:
    """sim_bridge and a random policy run together; the time limit stops both with exit 0."""
    params = tmp_path / 'params.yaml'
    params.write_text(
        'sim_bridge:\n  ros__parameters:\n    task: Cheetah-Run-v0\n    log_every: 50\n'
        'policy:\n  ros__parameters:\n    task: Cheetah-Run-v0\n')
    result = subprocess.run(
        [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params', str(params),
         '--nodes', 'sim_bridge,policy', '--timeout', '12'],
        cwd=REPO, env=ros_environment(fresh_domain_id()), capture_output=True, text=True,
        timeout=120, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert '[sim_bridge]' in result.stdout and 'step 50 ' in result.stdout
    assert 'time limit of 12.0 s reached' in result.stdout
