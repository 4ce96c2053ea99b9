"""Gymnasium interface: every task family (and any task file) as `zeus_ros/<task>`.

    import gymnasium
    import zeus_ros.gym_env  # registers zeus_ros/Cheetah-Run-v0, ... (or make with the
                             # id 'zeus_ros.gym_env:zeus_ros/Cheetah-Run-v0', no import needed)
    env = gymnasium.make('zeus_ros/Cheetah-Run-v0', schedule='switch:train:every=100',
                         obs='state', seed=0)
    zeus_ros.gym_env.register_task_file('params/tasks/payload_point_mass.yaml')
    env = gymnasium.make('zeus_ros/PointMass-Payload-v0')

It runs the one step loop every tool shares (`sim_bridge.env.ScheduledEnv`) with the schedule
syntax of `zeus collect`, so the same seed and actions give the same trajectory as a bag of
`zeus collect`. The context changes unannounced, as on the topics: `info['context']` carries
the true context (for oracle methods and logging), never the observation. Episodes end by time
limit only (`truncated`). `schedule` is the inline form of `zeus collect --schedule`, a schedule
YAML file, or the schedule mapping itself. `obs='pixels'` gives one HxWx3 frame per step
(stack frames with `gymnasium.wrappers.FrameStackObservation`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium
from gymnasium import spaces
import numpy as np

from sim_bridge.env import EnvStep, ScheduledEnv
from sim_bridge.registry import TASK_NAMES, make_task
from sim_bridge.registry import register_task_file as _register_file
from sim_bridge.schedules import schedule_from_config

__all__ = ['OBS_KINDS', 'ZeusEnv', 'register_envs', 'register_task_file']

OBS_KINDS = ('state', 'pixels')
NAMESPACE = 'zeus_ros'


class ZeusEnv(gymnasium.Env):
    """A contextual task under a context schedule, as a Gymnasium environment."""

    metadata = {'render_modes': ['rgb_array'], 'render_fps': 25}

    def __init__(self, task: str, schedule: str | Mapping[str, Any] = 'constant',
                 obs: str = 'state',
                 seed: int | None = None, image_size: int = 84,
                 render_mode: str | None = None) -> None:
        from zeus_ros.offline.rollout import parse_schedule

        if obs not in OBS_KINDS:
            raise ValueError(f'obs={obs!r}: choose one of {", ".join(OBS_KINDS)}')
        if render_mode not in (None, 'rgb_array'):
            raise ValueError(f"render_mode={render_mode!r}: only 'rgb_array' is supported")
        self.task_name, self.obs_kind, self.image_size = task, obs, int(image_size)
        self.render_mode = render_mode
        self._schedule_text = schedule
        self._schedule_config = dict(schedule) if isinstance(schedule, Mapping) \
            else parse_schedule(schedule)
        self._seed = 0 if seed is None else int(seed)
        self._env = self._build(self._seed)
        task_obj = self._env.task
        low, high = task_obj.action_bounds
        self.action_space = spaces.Box(low=low.astype(np.float32), high=high.astype(np.float32),
                                       dtype=np.float32, seed=self._seed)
        if obs == 'pixels':
            self.observation_space = spaces.Box(0, 255, (self.image_size, self.image_size, 3),
                                                dtype=np.uint8)
        else:
            self.observation_space = spaces.Box(-np.inf, np.inf, (task_obj.state_dim,),
                                                dtype=np.float64)
        self.context_names = task_obj.context_names

    def _build(self, seed: int) -> ScheduledEnv:
        """Task and schedule seeded as `zeus collect --seed` seeds them."""
        task = make_task(self.task_name, seed=seed)
        try:
            schedule = schedule_from_config(self._schedule_config, task, seed)
        except (KeyError, TypeError, ValueError) as error:
            task.close()
            raise ValueError(f'schedule {self._schedule_text!r}: {error}') from None
        return ScheduledEnv(task, schedule)

    def _observe(self, result: EnvStep) -> np.ndarray:
        if self.obs_kind == 'pixels':
            return self._env.task.render(self.image_size, self.image_size)
        return result.observation.state.astype(np.float64)

    @staticmethod
    def _info(result: EnvStep) -> dict[str, Any]:
        return {'context': dict(result.observation.context), 'step': result.step,
                'episode': result.episode, 'episode_step': result.episode_step,
                'segment': result.segment, 'action_status': int(result.status)}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        """A new episode; a seed restarts the run (task, schedule, step index) from it."""
        super().reset(seed=seed)
        if seed is not None:
            self._env.task.close()
            self._seed = int(seed)
            self._env = self._build(self._seed)
            self.action_space.seed(self._seed)
        result = self._env.reset()
        return self._observe(result), self._info(result)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One agent step (the task's action repeat); truncated at the episode's time limit."""
        result = self._env.step(np.asarray(action))
        reward = float(result.observation.reward)
        return (self._observe(result), reward, False, bool(result.observation.last),
                self._info(result))

    def render(self) -> np.ndarray | None:
        """An RGB frame of the task's camera (render_mode='rgb_array')."""
        if self.render_mode != 'rgb_array':
            return None
        return self._env.task.render(self.image_size, self.image_size)

    def close(self) -> None:
        """Release the renderer."""
        self._env.task.close()


def _register(name: str, task: str) -> str:
    env_id = f'{NAMESPACE}/{name}'
    if env_id not in gymnasium.registry:
        gymnasium.register(id=env_id, entry_point=f'{__name__}:ZeusEnv', kwargs={'task': task},
                           disable_env_checker=False)
    return env_id


def register_envs() -> list[str]:
    """Register every built-in family as zeus_ros/<task>; return the ids."""
    return [_register(name, name) for name in TASK_NAMES]


def register_task_file(path: str) -> str:
    """Register a task file's task as zeus_ros/<its name>; return the id."""
    return _register(_register_file(path), str(Path(path).resolve()))


register_envs()
