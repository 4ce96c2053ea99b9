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


MODULES = {'sim_bridge': 'sim_bridge_node', 'context_estimator': 'context_estimator_node',
           'policy': 'policy_node', 'recorder': 'recorder_node'}


def _param_args(params: tuple[str, ...]) -> list[str]:
    args: list[str] = []
    for param in params:
        args += ['-p', param]
    return args


def node(name: str, *params: str) -> list[str]:
    """Build the argv of a zeus_ros node with `-p` parameters given as 'key:=value' strings."""
    return python_module(f'zeus_ros.nodes.{MODULES[name]}', '--ros-args', *_param_args(params))


def container(nodes: dict[str, tuple[str, ...]], *process_args: str) -> list[str]:
    """The argv of one process holding `nodes` (name -> 'key:=value' parameters), one executor.

    `process_args` are the container's own (--no-intra-process).
    """
    args: list[str] = [*process_args]
    for name, params in nodes.items():
        args += ['--node', name, '--ros-args', *_param_args(params)]
    return python_module('zeus_ros.nodes.container', *args)


def check_lockstep_bag(bag_dir: Path, checkpoint: Path, steps: int, ns: str = '') -> None:
    """Lockstep held: the bag has an estimate and action per step, with that step's stamp.

    Every applied action came from the policy in time, and the bag ingests and trains.
    """
    import numpy as np
    from rosbags.highlevel import AnyReader

    from zeus_ros.learning.agent import make_agent
    from zeus_ros.learning.checkpoint import load_checkpoint
    from zeus_ros.offline.data.ingest import ingest_bags
    from zeus_ros.offline.data.replay import ReplayBuffer

    topics = {f'{ns}/zeus/{name}': name for name in ('action', 'context', 'step')}
    stamps: dict[str, dict[int, int]] = {}
    bags = sorted(path.parent for path in bag_dir.rglob('metadata.yaml'))
    with AnyReader(bags) as reader:
        for connection, _t, raw in reader.messages():
            if connection.topic in topics:
                msg = reader.deserialize(raw, connection.msgtype)
                stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
                stamps.setdefault(topics[connection.topic], {})[msg.step] = stamp
    recorded = sorted(stamps['step'])
    assert recorded == list(range(steps + 1))
    assert sorted(stamps['context']) == recorded, 'an estimate is missing for some step'
    assert set(range(steps)) <= set(stamps['action']), 'an action is missing'
    for step in range(steps):
        assert stamps['action'][step] == stamps['step'][step]
        assert stamps['context'][step] == stamps['step'][step]

    dataset = ingest_bags([bag_dir], strict=True)
    assert sum(len(e.action) for e in dataset.episodes) == steps
    statuses = np.concatenate([e.action_status[1:] for e in dataset.episodes])
    assert set(statuses.tolist()) == {1}, 'every applied action came from the policy in time'
    loaded = load_checkpoint(checkpoint)
    replay = ReplayBuffer(dataset, history=loaded.config.k, seed=0)
    agent = make_agent(loaded.config, loaded.spec)
    metrics = [agent.update(*replay.sample_pair(16), step=i) for i in range(4)]
    assert all(np.isfinite(v) for m in metrics for v in m.values())
