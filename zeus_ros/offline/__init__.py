"""Bags in, checkpoints out: collection, ingest, replay, training and evaluation (no ROS)."""
