"""Checkpoints and node commands shared by the live-system tests."""

from __future__ import annotations

from pathlib import Path

from ros_harness import python_module

TASK = 'Cheetah-Run-v0'


def tiny_checkpoint(path: Path, obs_kind: str = 'state', method: str = 'zeus') -> Path:
    """A real (untrained, small) checkpoint for the task: enough to exercise the nodes."""
    import numpy as np

    from sim_bridge.registry import make_task
    from zeus_ros.learning.agent import make_agent
    from zeus_ros.learning.checkpoint import save_checkpoint
    from zeus_ros.learning.config import ZeusConfig
    from zeus_ros.learning.spec import AgentSpec

    task = make_task(TASK)
    low, high = task.action_bounds
    obs_shape = (task.state_dim,) if obs_kind == 'state' else (9, 84, 84)
    spec = AgentSpec(
        task=TASK, context_names=task.context_names, obs_kind=obs_kind, obs_shape=obs_shape,
        action_dim=task.action_dim, action_low=low, action_high=high,
        obs_mean=np.zeros(obs_shape, np.float32) if obs_kind == 'state' else None,
        obs_std=np.ones(obs_shape, np.float32) if obs_kind == 'state' else None)
    config = ZeusConfig(method=method, obs_kind=obs_kind, hidden_dim=32, model_hidden_dim=32,
                        encoder_hidden_dim=32, context_hidden_dim=16, transition_dim=16,
                        feature_dim=16, num_filters=8, batch_size=16, device='cpu')
    task.close()
    save_checkpoint(path, make_agent(config, spec), step=0, extra={'purpose': 'test'})
    return path


def node(name: str, *params: str) -> list[str]:
    """Build the argv of a zeus_ros node with `-p` parameters given as 'key:=value' strings."""
    modules = {'sim_bridge': 'sim_bridge_node', 'context_estimator': 'context_estimator_node',
               'policy': 'policy_node', 'recorder': 'recorder_node'}
    args: list[str] = []
    for param in params:
        args += ['-p', param]
    return python_module(f'zeus_ros.nodes.{modules[name]}', '--ros-args', *args)
