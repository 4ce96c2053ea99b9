"""Real ROS 2 processes for tests: loopback-only discovery, one domain id per test, cleanup."""

from __future__ import annotations

from collections.abc import Callable, Iterator
import contextlib
from dataclasses import dataclass, field
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time
from typing import Any

from zeus_ros.system import processes

REPO = Path(__file__).resolve().parents[1]
LOG_DIR = REPO / 'log' / 'test-processes' / os.environ.get('PYTEST_XDIST_WORKER', '')
"""One folder per pytest-xdist worker, so that two tests' `sim_bridge.log` never mix."""


def require_ros() -> None:
    """Fail (never skip) with a clear message when the ROS environment is missing."""
    try:
        import rclpy  # noqa: F401
        import zeus_msgs.msg  # noqa: F401
    except ImportError as error:  # pragma: no cover - environment problem
        raise RuntimeError(
            f'ROS 2 environment missing ({error}): run the tests with `make test`, which builds '
            'zeus_msgs and sources scripts/env.sh'
        ) from error


def fresh_domain_id() -> int:
    """A domain id unlikely to clash with a parallel run (1..100, or $ZEUS_DOMAIN_RANGE)."""
    return processes.fresh_domain_id()


def ros_environment(domain_id: int) -> dict[str, str]:
    """Environment for a child ROS process: the project's (processes.ros_env), this domain."""
    return processes.ros_env(domain_id)


@dataclass
class ProcessGroup:
    """Child processes started for one test; `stop_all` always runs (fixture teardown)."""

    domain_id: int
    processes: list[tuple[str, subprocess.Popen[bytes]]] = field(default_factory=list)

    def start(self, name: str, argv: list[str], extra_env: dict[str, str] | None = None
              ) -> subprocess.Popen[bytes]:
        """Start `argv` in its own session, logging to log/test-processes/<name>.log."""
        LOG_DIR.mkdir(parents=True, exist_ok=True)
        env = ros_environment(self.domain_id)
        env.update(extra_env or {})
        log = open(LOG_DIR / f'{name}.log', 'wb')  # noqa: SIM115 - closed with the process
        process = processes.start_node(argv, env, stdout=log, cwd=REPO)
        self.processes.append((name, process))
        return process

    def log_text(self, name: str) -> str:
        """What the named process printed so far."""
        path = LOG_DIR / f'{name}.log'
        return path.read_text(errors='replace') if path.exists() else ''

    def wait_for_log(self, name: str, text: str, timeout: float = 60.0) -> None:
        """Block until the named process printed `text` (e.g. a readiness line); fail if not."""
        deadline = time.monotonic() + timeout
        while text not in self.log_text(name):
            if time.monotonic() > deadline:
                raise AssertionError(f'{name} did not print {text!r} within {timeout} s:\n'
                                     + self.log_text(name)[-2000:])
            time.sleep(0.05)

    def stop(self, process: subprocess.Popen[bytes], sig: int = signal.SIGINT,
             timeout: float = 10.0) -> int:
        """Signal a process group, wait, then escalate (processes.stop_nodes); the exit code."""
        processes.stop_nodes([process], sig=sig, deadline=time.monotonic() + timeout)
        return int(process.returncode)

    def stop_all(self) -> None:
        """Stop every process of the test, newest first."""
        for _name, process in reversed(self.processes):
            self.stop(process)


def child_pids(parent: int) -> dict[int, list[bytes]]:
    """Pid -> argv of every child of `parent` (e.g. the nodes a `zeus launch` started)."""
    found = {}
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / 'stat').read_text()
            argv = (entry / 'cmdline').read_bytes().split(b'\0')
        except OSError:
            continue
        if int(stat.rsplit(')', 1)[1].split()[1]) == parent:
            found[int(entry.name)] = argv
    return found


def stop_launch(launch: subprocess.Popen[str], grace: float = 30.0) -> None:
    """Make sure a `zeus launch` and every node it started are gone (a test's `finally`).

    Its nodes run in their own sessions, so killing the launcher's process group would leave
    them running (and loading the machine for every later test): SIGTERM lets the launcher stop
    them; whatever is still there after `grace` seconds gets SIGKILL.
    """
    if launch.poll() is not None:
        return
    nodes = child_pids(launch.pid)
    launch.terminate()
    try:
        launch.wait(timeout=grace)
    except subprocess.TimeoutExpired:
        launch.kill()
        launch.wait(timeout=10)
    for pid, argv in nodes.items():
        with contextlib.suppress(OSError):
            if (Path(f'/proc/{pid}') / 'cmdline').read_bytes().split(b'\0') == argv:
                os.kill(pid, signal.SIGKILL)


def read_until(launch: subprocess.Popen[str], text: str, lines: list[str],
               timeout: float = 120.0) -> None:
    """Read a launcher's output into `lines` until a line holds `text` (fail at timeout, EOF)."""
    assert launch.stdout is not None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = launch.stdout.readline()
        lines.append(line)
        if text in line or not line:
            break
    assert text in lines[-1], ''.join(lines[-30:])


@contextlib.contextmanager
def cpu_burners(count: int | None = None) -> Iterator[None]:
    """Busy-loop processes (one per core by default) for the block: start-up under load.

    Discovery and matching are slowest on a loaded machine; a test that must hold there runs
    its system inside this block. The burners are killed on leaving it, whatever happened.
    """
    burners = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
               for _ in range(count or os.cpu_count() or 1)]
    try:
        yield
    finally:
        for burner in burners:
            burner.kill()
            burner.wait(timeout=10)


def python_module(module: str, *args: str) -> list[str]:
    """Build the argv running `python -m module args` with this interpreter."""
    return [sys.executable, '-m', module, *args]


ros_context = processes.ros_context
"""An rclpy context of its own in the test process (zeus_ros.system.processes)."""


@contextlib.contextmanager
def driver_node(domain_id: int, name: str = 'test_driver') -> Iterator[Any]:
    """An rclpy node in the test process on its own context and domain; destroyed afterwards."""
    import rclpy

    with ros_context(domain_id) as context:
        node = rclpy.create_node(name, context=context)
        try:
            yield node
        finally:
            node.destroy_node()


def spin_until(node: Any, predicate: Callable[[], bool], timeout: float) -> bool:
    """Spin `node` until `predicate()` holds or `timeout` seconds pass; return the predicate."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    deadline = time.monotonic() + timeout
    try:
        while not predicate():
            if time.monotonic() > deadline:
                return False
            executor.spin_once(timeout_sec=0.05)
        return True
    finally:
        executor.remove_node(node)


def logged_at(text: str, needle: str = '') -> float:
    """The wall-clock stamp of the first ROS log line holding `needle` (nan: none).

    With no needle, the node's first line: it logs its checkpoint once the node exists.
    """
    for line in text.splitlines():
        stamp = re.match(r'\[\w+\] \[(\d+\.\d+)\]', line)
        if stamp and needle in line:
            return float(stamp.group(1))
    return float('nan')


def first_error_after(diagnostics: list[Any], heard: list[float], name: str, needle: str,
                 since: float) -> float:
    """Seconds from `since` to the first ERROR of `name` holding `needle` (inf: never)."""
    from diagnostic_msgs.msg import DiagnosticStatus

    for at, array in zip(heard, diagnostics, strict=True):
        if at >= since and any(s.name.startswith(f'{name}:') and s.level == DiagnosticStatus.ERROR
                               and needle in s.message for s in array.status):
            return at - since
    return float('inf')
