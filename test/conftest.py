"""Shared fixtures: ROS process groups that are always cleaned up; the fast lane (`--fast`).

`pytest --fast` (`make test-fast`) runs the pure tests only: it deselects every test marked
`ros` (real ROS 2 processes or rclpy in process; a test using the `ros_processes` fixture is
marked so here), `slow` (MuJoCo episodes, agent training, Ray, subprocess commands),
`faults_only` and `continual_live`. It lists at the end every test of the lane that took longer
than FAST_TEST_LIMIT_S: mark such a test `slow` so that the lane stays under FAST_LANE_BUDGET_S.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterator
import fcntl
import os
from pathlib import Path
import time

import pytest

from zeus_ros.system import processes

from ros_harness import ProcessGroup, fresh_domain_id, require_ros

os.environ.setdefault('MUJOCO_GL', 'egl')
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'


def _worker_domain_range() -> None:
    """Under pytest-xdist, give each worker its own slice of $ZEUS_DOMAIN_RANGE (default 1-100).

    Two tests running side by side then never draw the same ROS_DOMAIN_ID; children inherit it.
    """
    worker = os.environ.get('PYTEST_XDIST_WORKER')
    count = os.environ.get('PYTEST_XDIST_WORKER_COUNT')
    if not worker or not count:
        return
    first, last = processes.domain_range()
    size = (last - first + 1) // int(count)
    if size < 1:
        raise RuntimeError(f'{processes.DOMAIN_RANGE_ENV}={first}-{last} is too small for '
                           f'{count} pytest-xdist workers')
    start = first + int(worker.removeprefix('gw')) * size
    os.environ[processes.DOMAIN_RANGE_ENV] = f'{start}-{start + size - 1}'


_worker_domain_range()

FAST_LANE_EXCLUDES = ('ros', 'slow', 'faults_only', 'continual_live')
"""Markers whose tests the fast lane leaves out."""
FAST_TEST_LIMIT_S = 2.0
"""A test of the fast lane taking longer (setup + call + teardown) is named at the end."""
FAST_LANE_BUDGET_S = 60.0
"""`make test-fast` on the 2-core development machine, collection included."""


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption('--fast', action='store_true', default=False,
                     help='the fast lane: only tests not marked '
                          + ', '.join(FAST_LANE_EXCLUDES) + ' (make test-fast)')


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the users of `ros_processes` as `ros`; with --fast, deselect the lane's excludes."""
    for item in items:
        if 'ros_processes' in getattr(item, 'fixturenames', ()):
            item.add_marker(pytest.mark.ros)
    if not config.getoption('--fast'):
        return
    kept, dropped = [], []
    for item in items:
        excluded = any(item.get_closest_marker(name) for name in FAST_LANE_EXCLUDES)
        (dropped if excluded else kept).append(item)
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = kept


_durations: defaultdict[str, float] = defaultdict(float)
_started = time.monotonic()


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    _durations[report.nodeid] += report.duration


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter, exitstatus: int,
                            config: pytest.Config) -> None:
    """With --fast: the lane's wall time against its budget and every test over the limit."""
    if not config.getoption('--fast') or not _durations:
        return
    wall = time.monotonic() - _started
    over = sorted(((d, n) for n, d in _durations.items() if d > FAST_TEST_LIMIT_S), reverse=True)
    write = terminalreporter.write_line
    write(f'fast lane: {wall:.1f} s (budget {FAST_LANE_BUDGET_S:.0f} s), '
          f'{len(_durations)} tests')
    if over:
        write(f'fast lane: {len(over)} test(s) took more than {FAST_TEST_LIMIT_S:.0f} s; '
              'mark them @pytest.mark.slow (or ros):', yellow=True)
        for duration, nodeid in over:
            write(f'  {duration:6.1f} s  {nodeid}', yellow=True)


@pytest.fixture
def ros_processes() -> Iterator[ProcessGroup]:
    """A fresh domain id and a process group stopped at teardown, even when the test fails."""
    require_ros()
    group = ProcessGroup(domain_id=fresh_domain_id())
    try:
        yield group
    finally:
        group.stop_all()


ROS_FILE_MARKS = ('ros_environment(', 'require_ros(', 'fresh_domain_id(', 'ros_processes')
"""A test file that mentions one of these starts ROS 2 processes (or rclpy) in some test."""
_ros_files: dict[str, bool] = {}


def _starts_ros(item: pytest.Item) -> bool:
    """Marked `ros`, or in a file that starts ROS somewhere (not every such test is marked)."""
    if item.get_closest_marker('ros'):
        return True
    path = str(item.path)
    if path not in _ros_files:
        text = Path(path).read_text(encoding='utf-8', errors='replace')
        _ros_files[path] = any(mark in text for mark in ROS_FILE_MARKS)
    return _ros_files[path]


@pytest.fixture(autouse=True)
def _alone_when_marked(request: pytest.FixtureRequest,
                       tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Under pytest-xdist: `alone` tests run by themselves, `ros_quiet` ones beside no ROS system.

    Every test holds a shared lock on `alone.lock`, an `alone` test holds it exclusively. A test
    that starts ROS processes holds `ros.lock` shared, so two ROS systems may run side by side
    (each on its own domain id); a `ros_quiet` test holds it exclusively: side by side on two
    cores, a restarted policy was not re-paired in time and `zeus inspect` saw no step view
    before their deadlines (fresh-clone run, 2026-12-06). Timing-sensitive tests (a race
    against a settle time, steps counted against a killed process, a latency health check)
    are `alone`: they keep the quiet machine they were written for. `make test` runs the `alone`
    tests in a second phase without xdist (the wait for the other worker's current test to end
    left one worker idle); the lock serves a plain `pytest -n 2`.
    """
    if not os.environ.get('PYTEST_XDIST_WORKER'):
        yield
        return
    folder = Path(tmp_path_factory.getbasetemp()).parent
    exclusive = request.node.get_closest_marker('alone') is not None
    with (folder / 'alone.lock').open('a') as alone, (folder / 'ros.lock').open('a') as ros:
        fcntl.flock(alone, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        held = [alone]
        try:
            if not exclusive and _starts_ros(request.node):
                quiet = request.node.get_closest_marker('ros_quiet') is not None
                fcntl.flock(ros, fcntl.LOCK_EX if quiet else fcntl.LOCK_SH)
                held.append(ros)
            yield
        finally:
            for lock in reversed(held):
                fcntl.flock(lock, fcntl.LOCK_UN)
