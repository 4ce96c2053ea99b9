"""The ZeUS learning core: encoders, context model, SAC and baselines (PyTorch, no ROS)."""
