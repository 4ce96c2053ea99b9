"""zeus_ros: zero-shot adaptation to changing physics (ZeUS) as ROS 2 nodes."""

__version__ = '0.1.0'
