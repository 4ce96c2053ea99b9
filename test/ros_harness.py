"""Real ROS 2 processes for tests: loopback-only discovery, one domain id per test, cleanup."""

from __future__ import annotations

from collections.abc import Callable, Iterator
import contextlib
from dataclasses import dataclass, field
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import time
from typing import Any

REPO = Path(__file__).resolve().parents[1]
LOG_DIR = REPO / 'log' / 'test-processes'


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
    """A domain id in 1..100 (Fast DDS ports stay valid) unlikely to clash with a parallel run."""
    return random.SystemRandom().randint(1, 100)


def ros_environment(domain_id: int) -> dict[str, str]:
    """Environment for a child ROS process: loopback-only discovery and the given domain."""
    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('MUJOCO_GL', 'egl')
    return env


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
        process = subprocess.Popen(
            argv, cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT,
            start_new_session=True,
        )
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
        """Signal a process group, wait, and kill it if it does not exit in time."""
        if process.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, sig)
            try:
                process.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGKILL)
                process.wait(timeout=5)
        return int(process.returncode)

    def stop_all(self) -> None:
        """Stop every process of the test, newest first."""
        for _name, process in reversed(self.processes):
            self.stop(process)


def python_module(module: str, *args: str) -> list[str]:
    """Build the argv running `python -m module args` with this interpreter."""
    return [sys.executable, '-m', module, *args]


@contextlib.contextmanager
def driver_node(domain_id: int, name: str = 'test_driver') -> Iterator[Any]:
    """An rclpy node in the test process on its own context and domain; destroyed afterwards."""
    import rclpy
    from rclpy.context import Context

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node(name, context=context)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


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
