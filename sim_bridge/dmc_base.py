"""Shared step loop of the dm_control-suite tasks, on raw MuJoCo models that can be swapped.

The suite's `Physics`/`Task` objects are bound to one model; rebuilding them on every context
change costs ~4 ms of Python bookkeeping. The tasks here therefore reimplement the suite's
(small) observation, reward and episode-initialisation functions on `mujoco.MjModel`/`MjData`
(the tests compare them with dm_control on the default model) and swap models through
`ModelCache` + `copy_physical_state`.
"""

from __future__ import annotations

import abc
from collections.abc import Hashable, Mapping
import math

import mujoco
import numpy as np

from sim_bridge.core import ContextSpec, ContextualTask, StepResult
from sim_bridge.model_edit import (
    CompiledModel,
    ModelCache,
    SyncedRenderer,
    compile_spec,
    copy_physical_state,
    load_suite_spec,
)

__all__ = ['DmcTask', 'randomize_joints', 'validate_context']


def validate_context(
    task_name: str, specs: tuple[ContextSpec, ...], values: Mapping[str, float]
) -> dict[str, float]:
    """Check names, finiteness and ranges of a (partial) context; return it as plain floats."""
    by_name = {spec.name: spec for spec in specs}
    out: dict[str, float] = {}
    for name, raw in values.items():
        spec = by_name.get(name)
        if spec is None:
            raise ValueError(
                f'{task_name}: unknown context parameter {name!r}; valid: {sorted(by_name)}'
            )
        try:
            value = float(raw)
        except (TypeError, ValueError):
            raise ValueError(f'{task_name}: context {name}={raw!r} is not a number') from None
        if not math.isfinite(value) or not spec.low <= value <= spec.high:
            raise ValueError(
                f'{task_name}: context {name}={value} outside the accepted range '
                f'[{spec.low}, {spec.high}]'
            )
        out[name] = value
    return out


def randomize_joints(
    model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator, *, unlimited: bool
) -> None:
    """Sample limited hinge/slide joints uniformly in range (as dm_control's randomizers).

    With `unlimited`, unlimited hinges are also drawn from [-pi, pi] (walker, finger); unlimited
    slides are left alone. Ball and free joints do not occur in these tasks.
    """
    hinge, slide = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)
    for j in range(model.njnt):
        jtype = int(model.jnt_type[j])
        adr = model.jnt_qposadr[j]
        if jtype not in (hinge, slide):
            raise ValueError(f'joint {j} has unsupported type {jtype} for randomisation')
        if model.jnt_limited[j]:
            low, high = model.jnt_range[j]
            data.qpos[adr] = rng.uniform(low, high)
        elif unlimited and jtype == hinge:
            data.qpos[adr] = rng.uniform(-np.pi, np.pi)


class DmcTask(ContextualTask):
    """A suite task whose geometry context is applied by recompiling an edited `MjSpec`."""

    xml_name: str
    camera: int | str = 0
    """The camera frames come from: its index, or its name (task files, mjcf_task.py)."""
    n_sub_steps: int = 1
    """Physics steps per control step (the suite's control timestep / physics timestep)."""
    specs: tuple[ContextSpec, ...]
    model_params: tuple[str, ...]
    """Context names that change the compiled model; the others only change the reward."""

    def __init__(
        self,
        *,
        seed: int | None = None,
        context: Mapping[str, float] | None = None,
        episode_length: int | None = None,
        cache_size: int = 16,
    ) -> None:
        if episode_length is not None:
            if episode_length < 1:
                raise ValueError(f'{self.name}: episode_length must be >= 1, got {episode_length}')
            self.episode_length = int(episode_length)
        self._spec = self._load_spec(light_textures=True)
        self._prepare_spec(self._spec)
        self._cache = ModelCache(self._build, capacity=cache_size)
        self._context = {spec.name: float(spec.default) for spec in self.specs}
        if context:
            self._context.update(validate_context(self.name, self.specs, context))
        self._current: CompiledModel = self._cache.get(self._model_key(self._context))
        self._rng = np.random.default_rng(seed)
        self._renderer: SyncedRenderer | None = None
        self._episode_step = 0
        self._needs_reset = True
        low = self._current.model.actuator_ctrlrange[:, 0].astype(np.float32)
        high = self._current.model.actuator_ctrlrange[:, 1].astype(np.float32)
        self._bounds = (low, high)
        self._state_dim = int(self._observation(self._current.model, self._current.data).size)

    # --- what a concrete task provides -------------------------------------------------------

    def _load_spec(self, *, light_textures: bool) -> mujoco.MjSpec:
        """The task's model as an editable spec (the suite XML named by `xml_name`)."""
        return load_suite_spec(self.xml_name, light_textures=light_textures)

    def _suite_model(self) -> bool:
        """Whether the model is dm_control's suite XML (its own warnings are not the user's)."""
        return True

    def _prepare_spec(self, spec: mujoco.MjSpec) -> None:
        """Context-independent edits made once (e.g. explicit densities, contact priority)."""

    @abc.abstractmethod
    def _edit_spec(self, spec: mujoco.MjSpec, context: Mapping[str, float]) -> None:
        """Write the model-changing context values into the spec."""

    @abc.abstractmethod
    def _observation(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        """The flattened suite observation (float64, fixed order)."""

    @abc.abstractmethod
    def _reward(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> float:
        """Reward of one control step, evaluated after it."""

    @abc.abstractmethod
    def _initialize_episode(
        self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator
    ) -> None:
        """Set the initial state of an episode (data was reset to qpos0)."""

    # --- model management --------------------------------------------------------------------

    def _model_key(self, context: Mapping[str, float]) -> Hashable:
        return tuple(round(context[name], 12) for name in self.model_params)

    def _build(self, key: Hashable) -> mujoco.MjModel:
        assert isinstance(key, tuple)
        self._edit_spec(self._spec, dict(zip(self.model_params, key, strict=True)))
        return compile_spec(self._spec, suite=self._suite_model())

    @property
    def model(self) -> mujoco.MjModel:
        """The compiled model in force (read-only use: tests, benchmarks, inspection)."""
        return self._current.model

    @property
    def data(self) -> mujoco.MjData:
        """The simulation state in force (read-only use)."""
        return self._current.data

    @property
    def cache(self) -> ModelCache:
        """The compiled-model cache (its `compiles` counter shows recompiles)."""
        return self._cache

    # --- ContextualTask ----------------------------------------------------------------------

    @property
    def context_specs(self) -> tuple[ContextSpec, ...]:
        """The task's context parameters."""
        return self.specs

    @property
    def action_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Actuator control ranges of the model."""
        return self._bounds[0].copy(), self._bounds[1].copy()

    @property
    def state_dim(self) -> int:
        """Length of the flattened observation."""
        return self._state_dim

    @property
    def context(self) -> dict[str, float]:
        """The context in force now (a copy)."""
        return dict(self._context)

    @property
    def sim_time(self) -> float:
        """Physics time in seconds (kept across context changes)."""
        return float(self._current.data.time)

    @property
    def agent_period(self) -> float:
        """Simulated seconds per agent step: physics timestep x sub-steps x action repeat."""
        return float(self._current.model.opt.timestep) * self.n_sub_steps * self.action_repeat

    def set_context(self, values: Mapping[str, float]) -> None:
        """Swap in the model compiled for the new context; physical state carries over."""
        new = {**self._context, **validate_context(self.name, self.specs, values)}
        key = self._model_key(new)
        if key != self._model_key(self._context):
            entry = self._cache.get(key)
            old = self._current
            copy_physical_state(old.model, old.data, entry.model, entry.data)
            self._current = entry
        self._context = new

    def reset(self, seed: int | None = None) -> StepResult:
        """Start an episode: reset the data, randomise the initial pose as the suite does."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        model, data = self._current.model, self._current.data
        mujoco.mj_resetData(model, data)
        self._initialize_episode(model, data, self._rng)
        mujoco.mj_forward(model, data)
        self._episode_step = 0
        self._needs_reset = False
        return StepResult(
            state=self._observation(model, data),
            reward=0.0,
            first=True,
            last=False,
            context=self.context,
        )

    def step(self, action: np.ndarray) -> StepResult:
        """Apply the action for `action_repeat` control steps and sum the reward."""
        if self._needs_reset:
            raise RuntimeError(f'{self.name}: call reset() before step() (episode over or new)')
        act = np.asarray(action, dtype=np.float64).reshape(-1)
        if act.shape != (self.action_dim,):
            raise ValueError(
                f'{self.name}: action has {act.size} values, expected {self.action_dim}'
            )
        model, data = self._current.model, self._current.data
        data.ctrl[:] = act
        reward = 0.0
        for _ in range(self.action_repeat):
            mujoco.mj_step(model, data, nstep=self.n_sub_steps)
            # As the suite's Physics.step: position/velocity stages (kinematics, pos/vel sensors)
            # at the new state; acceleration-stage sensors (finger touch) and the solver warm
            # start keep the values of the last sub-step's solve (a full mj_forward would not).
            mujoco.mj_step1(model, data)
            reward += self._reward(model, data, act)
        return self._end_step(self._observation(model, data), reward)

    def render(self, height: int = 84, width: int = 84) -> np.ndarray:
        """RGB frame of the current state from the tracking camera."""
        if self._renderer is None:
            spec = self._load_spec(light_textures=False)
            self._prepare_spec(spec)
            self._edit_spec(spec, self._context)
            self._renderer = SyncedRenderer(compile_spec(spec, suite=self._suite_model()),
                                            camera=self.camera)
        return self._renderer.render(self._current.model, self._current.data, height, width)

    def close(self) -> None:
        """Free the renderer (its GL context)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
