"""Contextual MuJoCo tasks whose physics changes under the agent (pure Python, no ROS)."""
