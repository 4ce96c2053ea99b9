"""A node process whose paired-subscription callback raises (test_callback_errors.py).

`python failing_callback_node.py` runs, under the project's run_node (the default events
executor), a node that publishes on `boom` and takes it back through a SenderSubscription whose
callback raises TypeError on the third message.
"""

from __future__ import annotations

from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import String

from zeus_ros.nodes.sender_subscription import SenderSubscription
from zeus_ros.nodes.spin import run_node


class FailingNode(Node):
    """Publishes every 20 ms; its own paired subscription fails on the third message."""

    def __init__(self) -> None:
        super().__init__('failing_callback')
        self.taken = 0
        self._pub = self.create_publisher(String, 'boom', 10)
        self._sub = SenderSubscription(self, String, 'boom', QoSProfile(depth=10), self._on,
                                       lambda _gid: True)
        self.create_timer(0.02, lambda: self._pub.publish(String(data='x')))

    def _on(self, _msg: String) -> None:
        self.taken += 1
        if self.taken == 3:
            raise TypeError('a bug in a paired callback')


if __name__ == '__main__':
    run_node(FailingNode)
