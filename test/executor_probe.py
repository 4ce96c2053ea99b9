"""sim_bridge as its process runs it (spin.run_node), saying once which executor spins it.

    python test/executor_probe.py --ros-args -p task:=Cheetah-Run-v0

For test_executor.py: the executor a node reports is the one run_node added it to
($ZEUS_EXECUTOR), not what the test assumes.
"""

from __future__ import annotations

from typing import Any

from zeus_ros.nodes.sim_bridge_node import SimBridgeNode
from zeus_ros.nodes.spin import run_node

SAYS = 'spinning on '
"""The log line's prefix; the executor's class name follows."""


class ProbeBridge(SimBridgeNode):
    """sim_bridge plus a timer that logs `SAYS` + type(self.executor).__name__ once."""

    def __init__(self, **node_options: Any) -> None:
        super().__init__(**node_options)
        self._said = False
        self._say_timer = self.create_timer(0.05, self._say)

    def _say(self) -> None:
        if not self._said:
            self._said = True
            self.get_logger().info(SAYS + type(self.executor).__name__)


if __name__ == '__main__':
    run_node(ProbeBridge)
