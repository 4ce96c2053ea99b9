"""`zeus inspect` into a log file or a pipe: one line per update, every 10 s (issue 52, item 9).

On a terminal the view is a block (steps, segment return, each node's health) once a second;
redirected, that block every second filled logs with six lines a second. No ROS needed here:
the view's text is given, what is checked is what reaches the stream.
"""

from __future__ import annotations

import io

from zeus_ros.cli.inspect_topics import (
    PIPE_REFRESH_S,
    TERMINAL_REFRESH_S,
    Inspector,
    one_line,
    refresh_s,
)

BLOCK = ('[inspect] step 120 episode 0 segment 1 (H=32): torso_length: estimated 1.2, true 1.25\n'
         '          segment return 31.20 over 60 steps | 50 steps/s | latency p50 1.0 ms\n'
         '          sim_bridge: rate_hz=50.0\n'
         '          policy: STALE (no status for 6 s)\n')


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _inspector() -> Inspector:
    inspector = Inspector.__new__(Inspector)  # no ROS node: only the view's text matters here
    inspector.view = lambda: BLOCK.rstrip('\n')  # type: ignore[method-assign]
    return inspector


def test_a_pipe_gets_one_line_per_update_a_terminal_the_block() -> None:
    """Redirected: one line holding every part of the view; on a terminal the block itself."""
    piped, terminal = io.StringIO(), _Terminal()
    _inspector().show(piped)
    _inspector().show(terminal)
    line = piped.getvalue()
    assert line.count('\n') == 1, line
    for part in ('step 120', 'segment return 31.20', 'sim_bridge: rate_hz=50.0', 'STALE'):
        assert part in line
    assert terminal.getvalue() == BLOCK


def test_a_pipe_is_updated_less_often_unless_refresh_is_given() -> None:
    """10 s between lines redirected, 1 s on a terminal; --refresh wins either way."""
    assert refresh_s(io.StringIO(), None) == PIPE_REFRESH_S > TERMINAL_REFRESH_S
    assert refresh_s(_Terminal(), None) == TERMINAL_REFRESH_S
    assert refresh_s(io.StringIO(), 2.0) == refresh_s(_Terminal(), 2.0) == 2.0


def test_one_line_drops_the_blank_and_indent() -> None:
    assert one_line('a\n   b\n\n  c') == 'a | b | c'
