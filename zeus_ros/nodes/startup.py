"""A node process stopped while it starts exits quietly: no KeyboardInterrupt traceback.

Why (issue 49): `zeus launch` stopped while a policy was still importing torch printed a
KeyboardInterrupt traceback into the launch's output. From the moment `zeus_ros.nodes` is
imported by a process started as a node (`python -m zeus_ros.nodes.<node>`, as `zeus launch`
starts them, or an installed `<name>_node` / `loop_container` script), SIGINT and SIGTERM end it
at once with exit code 0, as a stop requested before it ran; `run_node` then installs its own
handlers (spin.py), which stop a running node in order. A library import (the CLI, the tests)
changes no handler.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from types import FrameType

__all__ = ['NODE_SCRIPTS', 'quiet_until_running', 'started_as_node']

NODE_SCRIPTS = frozenset({'sim_bridge_node', 'context_estimator_node', 'policy_node',
                          'recorder_node', 'robot_bridge_node', 'continual_trainer_node',
                          'loop_container'})
"""The console scripts setup.py installs for the node processes."""
NODE_PACKAGE = 'zeus_ros.nodes.'


def started_as_node(orig_argv: list[str] | None = None, argv0: str | None = None) -> bool:
    """Whether this process was started as a node (a node module run with -m, or its script)."""
    command = list(getattr(sys, 'orig_argv', []) if orig_argv is None else orig_argv)
    for index, word in enumerate(command[:-1]):
        if word == '-m':
            return command[index + 1].startswith(NODE_PACKAGE)
    script = sys.argv[0] if argv0 is None else argv0
    return os.path.basename(script) in NODE_SCRIPTS


def _stop_quietly(_signum: int, _frame: FrameType | None) -> None:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    os._exit(0)  # a stop asked for before the node ran: nothing to close, nothing to print


def quiet_until_running() -> bool:
    """Install the quiet stop for a process started as a node; True where it did."""
    if not started_as_node() or threading.current_thread() is not threading.main_thread():
        return False
    for stop_signal in (signal.SIGINT, signal.SIGTERM):
        signal.signal(stop_signal, _stop_quietly)
    return True
