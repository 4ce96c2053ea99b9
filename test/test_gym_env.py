"""The Gymnasium interface: env checker, every family registered, same trajectories as collect."""

from __future__ import annotations

from pathlib import Path
import warnings

import gymnasium
from gymnasium.utils.env_checker import check_env
import numpy as np
import pytest

from sim_bridge.registry import TASK_NAMES
import zeus_ros.gym_env as zeus_gym

from ros_harness import REPO

PAYLOAD = REPO / 'params' / 'tasks' / 'payload_point_mass.yaml'
EXPECTED_WARNINGS = ('infinity', 'out of date')
"""check_env warns about unbounded state spaces (as for gymnasium's own MuJoCo envs) and about
Cheetah-Run-v0 next to Cheetah-Run-v1 (two families here, not two versions of one)."""


def _checked(env_id: str, **kwargs: object) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        env = gymnasium.make(env_id, **kwargs)
        try:
            check_env(env.unwrapped)
        finally:
            env.close()
    unexpected = [str(w.message) for w in caught
                  if not any(text in str(w.message) for text in EXPECTED_WARNINGS)]
    assert not unexpected, unexpected


@pytest.mark.parametrize('task', TASK_NAMES)
def test_every_family_passes_the_env_checker(task: str) -> None:
    """State observations under a switching schedule, for every family."""
    _checked(f'zeus_ros/{task}', schedule='switch:train:every=10', obs='state', seed=0)


@pytest.mark.slow
def test_a_task_file_and_pixels_pass_the_env_checker() -> None:
    """A YAML task registered by file, with frames and rendering."""
    env_id = zeus_gym.register_task_file(str(PAYLOAD))
    assert env_id == 'zeus_ros/PointMass-Payload-v0'
    _checked(env_id, obs='pixels', render_mode='rgb_array', seed=1, image_size=32)


def test_info_carries_the_true_context_and_the_observation_never_does() -> None:
    """The context switches every 5 steps in info; the state vector keeps its task size."""
    env = gymnasium.make('zeus_ros/Cheetah-Run-v1', seed=0,
                         schedule={'kind': 'switch', 'every': 5, 'values': [0.5, 2.5]})
    try:
        obs, info = env.reset(seed=0)
        contexts = [info['context']['target_velocity']]
        for _ in range(12):
            obs, _r, terminated, _t, info = env.step(env.action_space.sample())
            contexts.append(info['context']['target_velocity'])
            assert obs.shape == (17,) and not terminated
    finally:
        env.close()
    assert contexts == [0.5] * 5 + [2.5] * 5 + [0.5] * 3


def test_gymnasium_and_zeus_collect_give_identical_trajectories(tmp_path: Path) -> None:
    """The actions of a `zeus collect` bag, replayed in the env with the same seed and schedule."""
    from zeus_ros.cli.collect import main as collect
    from zeus_ros.offline.data.ingest import ingest_bags

    schedule, seed = 'switch:train:every=30', 4
    assert collect(['--task-file', str(PAYLOAD), '--steps', '250', '--seed', str(seed),
                    '--schedule', schedule, '--out', str(tmp_path / 'bags'),
                    '--no-progress']) == 0
    episodes = ingest_bags([tmp_path / 'bags']).episodes
    assert len(episodes) >= 2  # an episode boundary (100 steps) is crossed
    env = gymnasium.make(zeus_gym.register_task_file(str(PAYLOAD)), schedule=schedule,
                         seed=seed)
    try:
        for number, episode in enumerate(episodes):
            obs, info = env.reset(seed=seed if number == 0 else None)
            np.testing.assert_array_equal(obs, episode.obs[0])
            for t, action in enumerate(episode.action):
                obs, reward, _term, truncated, info = env.step(action)
                np.testing.assert_array_equal(obs, episode.obs[t + 1])
                assert reward == pytest.approx(episode.reward[t], abs=1e-6)
                assert info['context']['payload_mass'] == pytest.approx(episode.context[t + 1, 0])
            assert truncated == (len(episode.action) == 100)
    finally:
        env.close()
