"""A node whose destroy hangs, run the way every zeus_ros node runs (spin.run_node).

`python hang_on_destroy.py gil|python`: `gil` blocks in C holding the GIL (libc sleep through
ctypes.PyDLL, as a hang inside rcl would: no Python signal handler can run), `python` loops in
Python ignoring every signal it notes. It logs `ready` once spinning.
"""

from __future__ import annotations

import ctypes
import sys
import time

from rclpy.node import Node

from zeus_ros.nodes.spin import run_node


class HangOnDestroy(Node):
    """Spins normally; its destroy_node never returns."""

    def __init__(self, how: str) -> None:
        super().__init__('hang_on_destroy')
        self.how = how
        self.create_timer(0.2, lambda: None)
        self.get_logger().info('ready')

    def destroy_node(self) -> None:
        """Never returns (what the policy did in 1 of 31 stops)."""
        print(f'destroy_node: hanging ({self.how})', file=sys.stderr, flush=True)
        libc = ctypes.PyDLL(None)
        while True:
            if self.how == 'gil':
                libc.sleep(3600)  # GIL held; a signal only ends this one call
            else:
                time.sleep(0.1)


if __name__ == '__main__':
    how = sys.argv[1]
    run_node(lambda: HangOnDestroy(how), sys.argv[2:])
