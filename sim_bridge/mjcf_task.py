"""A MuJoCo task declared in YAML: your MJCF, your observation, reward and context parameters.

It runs on the same machinery as the built-in families (`DmcTask`): context values are written
into an `MjSpec` and the model recompiled (masses and inertias follow geometry), compiled models
are cached, and a change mid-episode keeps positions, velocities and time. The file format
(example: params/tasks/payload_point_mass.yaml):

    name: PointMass-Payload-v0
    model: payload_point_mass.xml      # relative to this file; or suite:walker.xml
    n_sub_steps: 1                     # physics steps per control step
    action_repeat: 2                   # control steps per agent step (rewards summed)
    episode_length: 200                # agent steps
    init: random                       # qpos0 | random (limited joints) | random_all (+ hinges)
    camera: top                        # the camera of pixel observations (name or index)
    prepare: {'geom:floor.priority': 1}          # one-time edits (optional)
    observation: ['joint:*.qpos', 'joint:*.qvel', 'sensor:payload_acc.data']
    reward: 'tracking:root_x=0.1,root_y=0.1'     # built-in or package.module:function
    context:
      payload_mass:
        paths: ['geom:payload.mass']   # each path gets the value ...
        mapping: set                   # set: the value; scale: value x the model's default
        default: 0.2
        range: [0.01, 5.0]
    presets: {train: [...], interpolation: [...], extrapolation: [...]}

A path may also be `{path: 'body:bthigh.pos[0]', factor: -1.0, offset: 0.0}`: a dependent
quantity that follows the value (factor x value + offset), e.g. an attachment point.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
import math
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from sim_bridge.core import ContextSpec
from sim_bridge.dmc_base import DmcTask, randomize_joints
from sim_bridge.model_edit import load_model_spec, load_suite_spec
from sim_bridge.model_paths import ModelPath, parse_path
from sim_bridge.presets import SPLITS
from sim_bridge.rewards import JointObservation, load_reward

__all__ = ['ContextParam', 'MjcfTask', 'MjcfTaskSpec', 'parse_mjcf_task']

INITS = ('qpos0', 'random', 'random_all')
MAPPINGS = ('set', 'scale')
_KEYS = {'name', 'model', 'n_sub_steps', 'action_repeat', 'episode_length', 'init', 'camera',
         'prepare', 'observation', 'reward', 'context', 'presets',
         'varies', 'training', 'checkpoint', 'demo'}  # the last four: sim_bridge/families.py
_ONE_DOF = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


@dataclass(frozen=True)
class ContextParam:
    """One context parameter: the model paths it writes and how."""

    spec: ContextSpec
    mapping: str
    paths: tuple[tuple[ModelPath, float, float], ...]
    """(path, factor, offset): the path gets factor x value + offset (mapping 'set')."""


@dataclass(frozen=True)
class MjcfTaskSpec:
    """A validated task file."""

    name: str
    model: str
    source: Path
    n_sub_steps: int
    action_repeat: int
    episode_length: int
    init: str
    camera: int | str
    """The camera frames come from: its index or name in the model."""
    prepare: tuple[tuple[ModelPath, float], ...]
    observation: tuple[ModelPath, ...]
    reward: str
    context: tuple[ContextParam, ...]
    presets: dict[str, list[Any]] = field(default_factory=dict)

    def load_spec(self, *, light_textures: bool) -> mujoco.MjSpec:
        """The model as an editable spec."""
        if self.model.startswith('suite:'):
            return load_suite_spec(self.model[len('suite:'):], light_textures=light_textures)
        path = Path(self.model)
        if not path.is_absolute():
            path = self.source.parent / path
        if not path.is_file():
            raise ValueError(f'task file {self.source}: model {self.model!r} not found '
                             f'(looked at {path}; a path relative to the task file, or '
                             'suite:NAME.xml for a dm_control suite model)')
        return load_model_spec(path, light_textures=light_textures)


def _number(value: Any, where: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise ValueError(f'{where}: {value!r} is not a finite number')
    return number


def _integer(data: Mapping[str, Any], key: str, default: int, where: str) -> int:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f'{where}: {key} must be an integer >= 1, got {value!r}')
    return value


def _camera(value: Any, where: str) -> int | str:
    if isinstance(value, bool) or not isinstance(value, (int, str)) or value == '':
        raise ValueError(f'{where}: camera must be an index or a camera name, got {value!r}')
    return value


def _context_param(name: str, entry: Any, where: str) -> ContextParam:
    where = f'{where}: context {name}'
    if not isinstance(entry, Mapping):
        raise ValueError(f'{where}: expected a mapping with paths, mapping, default, range')
    unknown = sorted(set(entry) - {'paths', 'mapping', 'default', 'range', 'doc', 'unit'})
    if unknown:
        raise ValueError(f'{where}: unknown key(s) {unknown}; known: paths, mapping, default, '
                         'range, doc, unit')
    mapping = entry.get('mapping', 'set')
    if mapping not in MAPPINGS:
        raise ValueError(f'{where}: mapping {mapping!r}: choose set (the value) or scale '
                         "(the value times the model's default)")
    raw_paths = entry.get('paths')
    if isinstance(raw_paths, (str, Mapping)):
        raw_paths = [raw_paths]
    if not raw_paths:
        raise ValueError(f"{where}: paths is required, e.g. paths: ['geom:floor.friction[0]']")
    paths = []
    for item in raw_paths:
        if isinstance(item, Mapping):
            path = parse_path(item.get('path', ''))
            paths.append((path, _number(item.get('factor', 1.0), f'{where}: factor'),
                          _number(item.get('offset', 0.0), f'{where}: offset')))
        else:
            paths.append((parse_path(item), 1.0, 0.0))
    default = _number(entry.get('default', 1.0 if mapping == 'scale' else math.nan),
                      f'{where}: default')
    bounds = entry.get('range', [-math.inf, math.inf])
    if not isinstance(bounds, list) or len(bounds) != 2:
        raise ValueError(f'{where}: range must be [low, high]')
    low, high = (float(b) for b in bounds)
    if not low <= default <= high:
        raise ValueError(f'{where}: default {default} outside range [{low}, {high}]')
    return ContextParam(ContextSpec(name, default, low, high, str(entry.get('doc', '')),
                                    unit=str(entry.get('unit', ''))),
                        mapping, tuple(paths))


def parse_mjcf_task(path: Path, data: Mapping[str, Any]) -> MjcfTaskSpec:
    """Validate a task file's content; ValueError naming the file and the bad entry."""
    where = f'task file {path}'
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise ValueError(f'{where}: unknown key(s) {unknown}; known: {sorted(_KEYS)}')
    for key in ('name', 'model', 'observation', 'reward'):
        if not data.get(key):
            raise ValueError(f'{where}: {key} is required')
    init = data.get('init', 'qpos0')
    if init not in INITS:
        raise ValueError(f'{where}: init {init!r}: choose one of {", ".join(INITS)}')
    observation = data['observation']
    if isinstance(observation, str):
        observation = [observation]
    try:
        prepare = tuple((parse_path(key), _number(value, f'{where}: prepare {key}'))
                        for key, value in (data.get('prepare') or {}).items())
        obs = tuple(parse_path(item) for item in observation)
        context = data.get('context') or {}
        if not isinstance(context, Mapping):
            raise ValueError('context must map parameter names to their declarations')
        params = tuple(_context_param(str(name), entry, where) for name, entry in context.items())
    except ValueError as error:
        message = str(error)
        raise ValueError(message if message.startswith(where) else f'{where}: {message}'
                         ) from None
    presets = data.get('presets') or {}
    bad = sorted(set(presets) - set(SPLITS))
    if bad or not isinstance(presets, Mapping):
        raise ValueError(f'{where}: presets: splits are {", ".join(SPLITS)}; got {bad}')
    return MjcfTaskSpec(
        name=str(data['name']), model=str(data['model']), source=path,
        n_sub_steps=_integer(data, 'n_sub_steps', 1, where),
        action_repeat=_integer(data, 'action_repeat', 1, where),
        episode_length=_integer(data, 'episode_length', 1000, where), init=init,
        camera=_camera(data.get('camera', 0), where), prepare=prepare, observation=obs,
        reward=str(data['reward']), context=params, presets=dict(presets))


class MjcfTask(DmcTask):
    """A task file's MJCF model with its observation, reward and context paths."""

    def __init__(self, task_spec: MjcfTaskSpec, **kwargs: Any) -> None:
        self.task_spec = task_spec
        self.name = task_spec.name
        self.n_sub_steps = task_spec.n_sub_steps
        self.action_repeat = task_spec.action_repeat
        self.episode_length = task_spec.episode_length
        self.camera = task_spec.camera
        self.specs = tuple(param.spec for param in task_spec.context)
        self.model_params = tuple(spec.name for spec in self.specs)
        self._defaults: dict[str, list[list[np.ndarray]]] = {}
        self._obs_names: list[list[str]] | None = None
        self._reward_fn: Any = None
        self._prev: JointObservation | None = None
        try:
            super().__init__(**kwargs)
        except ValueError as error:
            where = f'task file {task_spec.source}'
            message = str(error)
            raise ValueError(message if message.startswith(where) else f'{where}: {message}'
                             ) from None
        model = self.model
        if isinstance(self.camera, str) and self.camera not in {
                model.camera(i).name for i in range(model.ncam)}:
            names = ', '.join(model.camera(i).name for i in range(model.ncam)) or 'none'
            raise ValueError(f"task file {task_spec.source}: no camera named {self.camera!r}; "
                             f"the model's cameras: {names}")
        joints = [model.joint(j).name for j in range(model.njnt) if model.jnt_type[j] in _ONE_DOF]
        try:
            self._reward_fn = load_reward(task_spec.reward, joints, ('position', 'velocity'))
        except ValueError as error:
            raise ValueError(f'task file {task_spec.source}: {error}') from None

    def _load_spec(self, *, light_textures: bool) -> mujoco.MjSpec:
        return self.task_spec.load_spec(light_textures=light_textures)

    def _suite_model(self) -> bool:
        """`model: suite:NAME.xml`: dm_control's file; a user's own MJCF keeps its warnings."""
        return self.task_spec.model.startswith('suite:')

    def _prepare_spec(self, spec: mujoco.MjSpec) -> None:
        """One-time edits, then the defaults the `scale` mapping multiplies (validates paths)."""
        for path, value in self.task_spec.prepare:
            path.spec_write(spec, [np.asarray([value])] * len(path.spec_read(spec)))
        self._defaults = {param.spec.name: [path.spec_read(spec) for path, _f, _o
                                            in param.paths]
                          for param in self.task_spec.context}

    def _edit_spec(self, spec: mujoco.MjSpec, context: Mapping[str, float]) -> None:
        for param in self.task_spec.context:
            value = context[param.spec.name]
            for (path, factor, offset), defaults in zip(param.paths,
                                                        self._defaults[param.spec.name],
                                                        strict=True):
                if param.mapping == 'scale':
                    values = [default * value for default in defaults]
                else:
                    values = [np.full_like(default, factor * value + offset)
                              for default in defaults]
                path.spec_write(spec, values)

    def _observation(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        if self._obs_names is None:
            self._obs_names = [path.data_names(model) for path in self.task_spec.observation]
        return np.concatenate([path.data_read(data, names) for path, names
                               in zip(self.task_spec.observation, self._obs_names, strict=True)])

    def _named(self, model: mujoco.MjModel, data: mujoco.MjData) -> JointObservation:
        """The observation with names, for the reward (1-dof joints, sensors by name)."""
        joints = [model.joint(j) for j in range(model.njnt) if model.jnt_type[j] in _ONE_DOF]
        return JointObservation(
            state=self._observation(model, data),
            position={j.name: float(data.qpos[j.qposadr[0]]) for j in joints},
            velocity={j.name: float(data.qvel[j.dofadr[0]]) for j in joints},
            extra={model.sensor(s).name: data.sensor(s).data.copy()
                   for s in range(model.nsensor)},
            model=model, data=data)

    def _reward(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> float:
        obs = self._named(model, data)
        reward = float(self._reward_fn(obs, action, self._prev))
        self._prev = obs
        return reward

    def _initialize_episode(self, model: mujoco.MjModel, data: mujoco.MjData,
                            rng: np.random.Generator) -> None:
        self._prev = None
        if self.task_spec.init != 'qpos0':
            randomize_joints(model, data, rng, unlimited=self.task_spec.init == 'random_all')
