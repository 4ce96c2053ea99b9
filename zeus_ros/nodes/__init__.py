"""ROS 2 nodes: thin adapters between messages and the arrays of the learning core."""

from zeus_ros.nodes.startup import quiet_until_running

quiet_until_running()  # a node process stopped while importing exits without a traceback
