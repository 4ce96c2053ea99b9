"""A node process never hangs at shutdown: each stop phase has a time limit, then it exits.

Why: one policy process (1 of 31 stops) spun inside `destroy_node` after Ctrl-C and survived
SIGINT and SIGTERM; its Python signal handlers could not run while rcl held the main thread.
The limits are enforced by faulthandler's watchdog, a C thread that needs no GIL and no Python
signal handler: when a phase overruns, it prints every thread's stack (where it hung) to
stderr and ends the process with exit code 1, which `zeus launch` reports.
"""

from __future__ import annotations

from collections.abc import Iterator
import contextlib
import faulthandler
import os

__all__ = ['DESTROY_LIMIT_S', 'LIMIT_ENV', 'STOP_LIMIT_S', 'bounded', 'start_stop_limit']

STOP_LIMIT_S = 30.0
"""From the first stop signal to the exit: a recorder's drain, the delivery of what a node
published last, destroy and close fit well within it (a few seconds each at most)."""
DESTROY_LIMIT_S = 5.0
"""Removing the nodes from the executor and destroying them; then rclpy's shutdown."""
LIMIT_ENV = 'ZEUS_DESTROY_LIMIT_S'
"""Overrides DESTROY_LIMIT_S (seconds > 0): the fault test shortens it."""


def destroy_limit() -> float:
    """DESTROY_LIMIT_S, or $ZEUS_DESTROY_LIMIT_S where set to a positive number."""
    try:
        value = float(os.environ.get(LIMIT_ENV, '') or DESTROY_LIMIT_S)
    except ValueError:
        return DESTROY_LIMIT_S
    return value if value > 0 else DESTROY_LIMIT_S


def start_stop_limit() -> None:
    """Called on the first stop signal: the whole stop must end within STOP_LIMIT_S."""
    faulthandler.dump_traceback_later(STOP_LIMIT_S, exit=True)


@contextlib.contextmanager
def bounded(seconds: float | None = None) -> Iterator[None]:
    """Run the block under a hard limit (default destroy_limit()): past it, stacks and exit 1.

    Leaving the block lifts the limit, including the stop limit a signal set.
    """
    faulthandler.dump_traceback_later(destroy_limit() if seconds is None else seconds,
                                      exit=True)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
