"""Checkpoints, node commands and bag checks shared by the live-system and bag tests."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ros_harness import python_module

TASK = 'Cheetah-Run-v0'


def tiny_checkpoint(path: Path, obs_kind: str = 'state', method: str = 'zeus',
                    seed: int = 0, task_name: str = TASK) -> Path:
    """A real (untrained, small) checkpoint for the task: enough to exercise the nodes.

    The same arguments give the same bytes; another `seed` gives other weights.
    """
    import numpy as np

    from sim_bridge.registry import make_task
    from zeus_ros.learning.agent import make_agent
    from zeus_ros.learning.checkpoint import save_checkpoint
    from zeus_ros.learning.config import ZeusConfig
    from zeus_ros.learning.spec import AgentSpec

    task = make_task(task_name)
    low, high = task.action_bounds
    obs_shape = (task.state_dim,) if obs_kind == 'state' else (9, 84, 84)
    spec = AgentSpec(
        task=task_name, context_names=task.context_names, obs_kind=obs_kind, obs_shape=obs_shape,
        action_dim=task.action_dim, action_low=low, action_high=high,
        obs_mean=np.zeros(obs_shape, np.float32) if obs_kind == 'state' else None,
        obs_std=np.ones(obs_shape, np.float32) if obs_kind == 'state' else None)
    config = ZeusConfig(method=method, obs_kind=obs_kind, hidden_dim=32, model_hidden_dim=32,
                        encoder_hidden_dim=32, context_hidden_dim=16, transition_dim=16,
                        feature_dim=16, num_filters=8, batch_size=16, device='cpu', seed=seed)
    task.close()
    save_checkpoint(path, make_agent(config, spec), step=0, extra={'purpose': 'test'})
    return path


MODULES = {'sim_bridge': 'sim_bridge_node', 'context_estimator': 'context_estimator_node',
           'policy': 'policy_node', 'recorder': 'recorder_node',
           'robot_bridge': 'robot_bridge_node'}


def _param_args(params: tuple[str, ...]) -> list[str]:
    args: list[str] = []
    for param in params:
        args += ['-p', param]
    return args


LOOP_GROUP = ('sim_bridge', 'context_estimator', 'policy', 'recorder')
"""The nodes of a recorded lockstep loop, as `zeus launch --record` starts them."""


def start_gates(name: str, group: tuple[str, ...] = LOOP_GROUP) -> tuple[str, ...]:
    """The start-up parameters a launcher gives node `name` in `group`, as 'key:=value'.

    Nodes started one by one need them as much as a launch does: without them a reader whose
    side of a match comes late (the recorder's, on a loaded machine) misses the first steps.
    """
    from zeus_ros.system.launch_defaults import start_args

    return tuple(start_args(name, group)[1::2])  # without the '-p's


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


def assert_ingests_as_one_by_one(paths: list[Path], monkeypatch: Any) -> None:
    """Ingest's batches (cdr_columns: decoding, stacking) give what one-by-one decoding gives.

    The reference is ingest with rosbags decoding every message alone (as before issue 14):
    the same episodes, array for array (dtype, shape, NaN where NaN), and the same issues.
    """
    import dataclasses
    import warnings

    import numpy as np

    from zeus_ros.bags import cdr_columns
    from zeus_ros.offline.data import ingest

    def one_by_one(raws: list[bytes], _msgtype: str, one: Any) -> list[Any]:
        out = []
        for index in range(len(raws)):
            message = one(index)
            stamp = message.header.stamp
            out.append(cdr_columns._with_stamp(message, stamp.sec * 10**9 + stamp.nanosec))
        return out

    with warnings.catch_warnings():
        warnings.simplefilter('ignore', ingest.IngestWarning)
        batched = ingest.ingest_bags(paths)
        monkeypatch.setattr(ingest, 'decode_messages', one_by_one)
        alone = ingest.ingest_bags(paths)
        monkeypatch.undo()
    assert batched.report.issues == alone.report.issues
    assert (batched.report.steps, batched.report.dropped) == (alone.report.steps,
                                                            alone.report.dropped)
    assert len(batched.episodes) == len(alone.episodes) > 0
    for ours, theirs in zip(batched.episodes, alone.episodes, strict=True):
        for item in dataclasses.fields(ours):
            a, b = getattr(ours, item.name), getattr(theirs, item.name)
            if isinstance(b, np.ndarray):
                assert a.dtype == b.dtype and a.shape == b.shape, item.name
                np.testing.assert_array_equal(a, b, err_msg=item.name)
            else:
                assert a == b, item.name
