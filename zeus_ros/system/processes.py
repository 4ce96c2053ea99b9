"""Node processes with the project's environment, started and stopped one way.

`zeus launch` (cli.launch.Supervisor), the demo (through the same Supervisor) and the test harness
(test/ros_harness.py) all start their ROS children here: loopback-only discovery, one domain id
for the group, unbuffered output, each child in its own session (a signal reaches the node and
whatever it spawned). Stopping escalates: SIGINT (the node closes its bag or files), then SIGTERM
after the grace period, then SIGKILL, so a node that ignores one signal still ends.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
import contextlib
import ctypes
import os
from pathlib import Path
import random
import signal
import subprocess
import time
from typing import IO, Any

__all__ = ['DOMAIN_RANGE_ENV', 'KILL_WAIT_S', 'TERM_GRACE_S', 'background_priority',
           'die_with_parent', 'domain_range',
           'fresh_domain_id',
           'group_domain_id',
           'ros_context', 'ros_env', 'start_node', 'stop_nodes']

DOMAIN_RANGE_ENV = 'ZEUS_DOMAIN_RANGE'
"""'FIRST-LAST': where fresh domain ids are drawn (default 1-100), so parallel users keep apart."""
TERM_GRACE_S = 3.0
"""How long a node that outlived its SIGINT grace gets after SIGTERM before SIGKILL."""
KILL_WAIT_S = 5.0
"""How long to wait for the kernel to reap a SIGKILLed node."""


def domain_range() -> tuple[int, int]:
    """(first, last) of $ZEUS_DOMAIN_RANGE (default 1-100: Fast DDS ports stay valid)."""
    text = os.environ.get(DOMAIN_RANGE_ENV, '1-100')
    first, _sep, last = text.partition('-')
    try:
        low, high = int(first), int(last or first)
    except ValueError:
        raise ValueError(f'{DOMAIN_RANGE_ENV}={text}: expected FIRST-LAST, e.g. 200-219') from None
    if not 0 <= low <= high <= 232:
        raise ValueError(f'{DOMAIN_RANGE_ENV}={text}: domain ids must lie in 0..232')
    return low, high


def fresh_domain_id() -> int:
    """A random domain id in $ZEUS_DOMAIN_RANGE (domain_range)."""
    return random.SystemRandom().randint(*domain_range())


def group_domain_id(wanted: int | None = None) -> int:
    """The domain of a group: `wanted`, else $ROS_DOMAIN_ID, else a fresh one."""
    if wanted is not None:
        return wanted
    return int(os.environ.get('ROS_DOMAIN_ID') or fresh_domain_id())


def loopback_dds_profile() -> Path | None:
    """params/dds/fastdds_loopback.xml (checkout or installed share): RTPS on loopback only.

    A user's own FASTRTPS_DEFAULT_PROFILES_FILE (several machines) is left as it is by callers.
    """
    from zeus_ros.system.launch_defaults import share_dir

    for base in (Path(__file__).resolve().parents[2], share_dir()):
        candidate = base / 'params' / 'dds' / 'fastdds_loopback.xml'
        if candidate.is_file():
            return candidate
    return None


def ros_env(domain_id: int | None = None) -> dict[str, str]:
    """The children's environment: loopback-only discovery and one domain id for the group."""
    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    profile = loopback_dds_profile()
    if profile is not None:
        env.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', str(profile))
    env['ROS_DOMAIN_ID'] = str(group_domain_id(domain_id))
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('MUJOCO_GL', 'egl')
    return env


@contextlib.contextmanager
def ros_context(domain_id: int) -> Iterator[Any]:
    """An rclpy context of this process's own on `domain_id`, loopback-only discovery.

    For a test or benchmark that talks to the nodes it started from its own process: the
    caller's default context (a test's) is left alone, and the context is shut down on leaving.
    """
    import rclpy
    from rclpy.context import Context

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    profile = loopback_dds_profile()
    if profile is not None:  # read by Fast DDS when this process makes its first participant
        os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', str(profile))
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


def start_node(argv: Sequence[str], env: dict[str, str], *, stdout: int | IO[bytes],
               cwd: Path | None = None) -> subprocess.Popen[bytes]:
    """Start one child in its own session, stderr merged into `stdout` (a PIPE or a file)."""
    return subprocess.Popen(list(argv), cwd=cwd, env=env, stdout=stdout,
                            stderr=subprocess.STDOUT, start_new_session=True)


def _signal(process: subprocess.Popen[bytes], sig: int) -> None:
    if process.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, sig)


def _wait(process: subprocess.Popen[bytes], seconds: float) -> bool:
    try:
        process.wait(timeout=max(0.1, seconds))
    except subprocess.TimeoutExpired:
        return False
    return True


def stop_nodes(processes: Sequence[subprocess.Popen[bytes]], *, deadline: float,
               sig: int = signal.SIGINT, term_grace: float = TERM_GRACE_S) -> None:
    """Stop children together: `sig` to every one at once, then escalate per child.

    Each gets until `deadline` (time.monotonic()); one still running gets SIGTERM and
    `term_grace` seconds more, then SIGKILL.
    """
    for process in processes:
        _signal(process, sig)
    for process in processes:
        if _wait(process, deadline - time.monotonic()):
            continue
        if sig not in (signal.SIGTERM, signal.SIGKILL):
            _signal(process, signal.SIGTERM)
            if _wait(process, term_grace):
                continue
        _signal(process, signal.SIGKILL)
        process.wait(timeout=KILL_WAIT_S)


def _prctl() -> Any:
    """The C library's prctl, looked up at import (no dlopen between fork and exec)."""
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (AttributeError, OSError):  # not Linux
        return None


_PRCTL = _prctl()


def die_with_parent(sig: int = signal.SIGTERM) -> bool:
    """In a child (or a preexec_fn): get `sig` when the parent dies (PR_SET_PDEATHSIG).

    So no training outlives the worker or node that started it. False where prctl is missing
    (not Linux): the parent's own shutdown has to stop the child then.
    """
    if _PRCTL is None:
        return False
    _PRCTL(1, sig)
    return True


def background_priority(nice: int, batch: bool) -> str:
    """Make this process (and what it starts) background work; what was applied, in words.

    `batch`: Linux SCHED_BATCH (no root needed). The process keeps its fair share of the CPU
    beside other work at the same nice (a trainer at nice 10 on a busy machine took 11-17
    minutes to its first decision), but is never favoured on a wake-up, so the control
    loop's processes, which sleep between steps and wake for each, still run first when they
    wake. `nice` lowers its share further (the
    process's and, with autogroup, its session's).
    """
    applied = []
    if nice:
        os.nice(int(nice))
        applied.append(f'nice {os.nice(0)}')
        # With autogroup (the default of most Linux kernels) a nice value only orders the
        # processes of one session: each node runs in a session of its own, so the niced
        # trainer would still get a session's full share. Its session's nice says it across.
        with contextlib.suppress(OSError):
            Path('/proc/self/autogroup').write_text(str(os.nice(0)))
            applied.append(f'autogroup nice {os.nice(0)}')
    if batch and hasattr(os, 'sched_setscheduler') and hasattr(os, 'SCHED_BATCH'):
        try:
            os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
            applied.append('SCHED_BATCH')
        except OSError as error:
            applied.append(f'no SCHED_BATCH ({error.strerror})')
    return ', '.join(applied) or 'normal priority'
