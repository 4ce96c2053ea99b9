"""Bags in, checkpoints out (no ROS): data/ (bags), training/ (runs), evaluation/ (results)."""
