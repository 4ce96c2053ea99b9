"""A bug in a callback ends a node with its traceback and exit 1, never a SIGSEGV.

rclpy's EventsExecutor (Jazzy, the nodes' default) turns an exception raised inside a Waitable
into a segmentation fault with no Python traceback; the nodes' paired subscriptions are
Waitables (sender_subscription.py). Found when a renamed method made every default launch's
estimator die with exit code -11 and nothing said why.
"""

from __future__ import annotations

from pathlib import Path
import subprocess
import sys

import pytest

from ros_harness import fresh_domain_id, require_ros, ros_environment

NODE = Path(__file__).with_name('failing_callback_node.py')


@pytest.mark.ros
@pytest.mark.parametrize('executor', ['events', 'single'])
def test_a_failing_paired_callback_exits_1_with_its_traceback(executor: str) -> None:
    require_ros()
    env = {**ros_environment(fresh_domain_id()), 'ZEUS_EXECUTOR': executor}
    done = subprocess.run([sys.executable, str(NODE)], env=env, capture_output=True,
                          text=True, timeout=60, check=False)
    assert done.returncode == 1, (done.returncode, done.stderr[-2000:])
    assert 'TypeError: a bug in a paired callback' in done.stderr, done.stderr[-2000:]
    assert 'in _on' in done.stderr and 'Segmentation fault' not in done.stderr
