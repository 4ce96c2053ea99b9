"""Runs that make checkpoints: collection, training, the collect-train loop, sweeps."""
