"""Shared fixtures: ROS process groups that are always cleaned up."""

from __future__ import annotations

from collections.abc import Iterator
import os

import pytest

from ros_harness import ProcessGroup, fresh_domain_id, require_ros

os.environ.setdefault('MUJOCO_GL', 'egl')
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'


@pytest.fixture
def ros_processes() -> Iterator[ProcessGroup]:
    """A fresh domain id and a process group stopped at teardown, even when the test fails."""
    require_ros()
    group = ProcessGroup(domain_id=fresh_domain_id())
    try:
        yield group
    finally:
        group.stop_all()
