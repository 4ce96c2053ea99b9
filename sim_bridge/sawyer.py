"""Sawyer-Peg-v0: put a peg held by a Sawyer arm into a box whose position is the hidden context.

The task follows MELD's peg insertion (REFERENCES.md 1.1; tonyzhaozh/meld,
`peg/sawyer_peg.py` and `reacher/sawyer_reacher.py`), ported from mujoco-py to `mujoco`:

- **Context** `goal_x`, `goal_y`: position of the box with the hole, written into `body_pos` as
  MELD's `set_task_for_env` does. The box is static, so the write is valid at any step and keeps
  qpos/qvel/time; no recompile is needed.
- **Reward** (paper appendix B.2: MELD's formula *without* the offset of its implementation):
  d = 5 ||peg_tip - goal||, r = -(d^2 + log10(d^2 + 1e-5)), plus MELD's sparse margin of 1 when
  d < 0.15 (peg tip within 3 cm of the floor of the hole). MELD exposes that sparse signal as an
  extra observation channel; here it is added to the one scalar reward so that success is visible
  to the learner without putting reward (and thus the context) into the state.
- **Action** (deviation, documented): MELD commands 7 joint-position deltas of at most 0.04 rad
  through position servos. Here the action is a 3-D Cartesian delta of the peg, each axis in
  [-1, 1] scaled to `ACTION_SCALE` metres, applied through a mocap weld that also keeps the peg
  vertical and square to the box. It needs no inverse kinematics, cannot wind up against the box
  (the target is re-based on the measured peg position every step) and makes the insertion
  reachable within the 40-step horizon.
- **Timing**: 2.5 ms physics step, 100 physics steps (0.25 s) per agent step, as MELD's
  `frame_skip`; 40 agent steps per episode (paper table "common hyper-parameters").
- **Start**: MELD's home joint angles, settled once under the weld; deterministic, as in MELD.
- **State**: joint positions (7), joint velocities (7), peg-tip position (3), float64. MELD also
  appends the last rewards; they are left out because they reveal the context.
"""

from __future__ import annotations

from collections.abc import Mapping
import copy
import functools
from pathlib import Path

import mujoco
import numpy as np

from sim_bridge.core import ContextSpec, ContextualTask, StepResult
from sim_bridge.dmc_base import validate_context
from sim_bridge.families import DeclaredSpecs
from sim_bridge.model_edit import SyncedRenderer

__all__ = ['ACTION_SCALE', 'SawyerPegTask', 'peg_reward']

XML_PATH = Path(__file__).resolve().parent / 'assets' / 'sawyer' / 'sawyer_peg.xml'
ACTION_SCALE = 0.025
"""Metres the peg target moves per agent step for an action component of 1."""
SUB_STEPS = 100
"""Physics steps per agent step (MELD's frame_skip)."""
DIST_SCALE = 5.0
"""MELD multiplies the tip-goal distance by 5 before shaping."""
SPARSE_RADIUS = 0.15
"""Scaled distance under which MELD's sparse margin is paid (3 cm unscaled)."""
SPARSE_MARGIN = 1.0
LOG_EPS = 1e-5
# Box of reachable peg-body targets [m]: over the table, with the peg tip (3 cm below the body
# origin) never below the table top, so the target cannot be driven into the table.
_TARGET_LOW = np.array([0.3, -0.4, 0.03])
_TARGET_HIGH = np.array([0.85, 0.4, 0.4])
_SETTLE_STEPS = 800  # 2 s: the weld turns the home pose's slightly tilted peg vertical


def peg_reward(tip: np.ndarray, goal: np.ndarray) -> float:
    """MELD's peg reward without its offset term, plus the sparse margin near the goal."""
    dist = DIST_SCALE * float(np.linalg.norm(np.asarray(tip) - np.asarray(goal)))
    reward = -(dist**2 + np.log10(dist**2 + LOG_EPS))
    if dist < SPARSE_RADIUS:
        reward += SPARSE_MARGIN
    return float(reward)


@functools.lru_cache(maxsize=1)
def _base_model() -> tuple[mujoco.MjModel, np.ndarray, np.ndarray]:
    """Compile the XML once per process and find the settled start (qpos, mocap position).

    Compiling the meshes costs ~0.2 s; every task instance gets its own copy of the model
    because the context writes into `body_pos`.
    """
    model = mujoco.MjModel.from_xml_path(str(XML_PATH))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key('home').id)
    mujoco.mj_kinematics(model, data)
    peg = model.body('peg').id
    data.mocap_pos[0] = data.xpos[peg]
    mujoco.mj_step(model, data, nstep=_SETTLE_STEPS)
    mujoco.mj_kinematics(model, data)
    return model, data.qpos.copy(), data.xpos[peg].copy()


class SawyerPegTask(ContextualTask):
    """Sawyer-Peg-v0: reach into the box with the peg; the box position is the context."""

    name = 'Sawyer-Peg-v0'
    action_repeat = 1
    episode_length = 40
    specs = DeclaredSpecs()  # params/tasks/<name>.yaml

    def __init__(
        self, *, seed: int | None = None, context: Mapping[str, float] | None = None
    ) -> None:
        base, self._home_qpos, self._home_target = _base_model()
        self._model = copy.copy(base)
        self._data = mujoco.MjData(self._model)
        self._box = self._model.body('box').id
        self._peg = self._model.body('peg').id
        self._tip = self._model.site('peg_tip').id
        self._goal = self._model.site('goal').id
        self._camera = self._model.camera('track').id
        self._home_quat = self._model.body_quat[self._model.body('mocap').id].copy()
        self._rng = np.random.default_rng(seed)  # kept for the common API: the start is fixed
        self._context = {spec.name: float(spec.default) for spec in self.specs}
        self._renderer: SyncedRenderer | None = None
        self._episode_step = 0
        self._needs_reset = True
        self.set_context(context or {})
        self._start()

    # --- ContextualTask ----------------------------------------------------------------------

    @property
    def context_specs(self) -> tuple[ContextSpec, ...]:
        """The goal position parameters."""
        return self.specs

    @property
    def action_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Cartesian peg deltas, each axis in [-1, 1] (x `ACTION_SCALE` metres)."""
        return -np.ones(3, dtype=np.float32), np.ones(3, dtype=np.float32)

    @property
    def state_dim(self) -> int:
        """Joint positions (7) + joint velocities (7) + peg tip (3)."""
        return self._model.nq + self._model.nv + 3

    @property
    def sim_time(self) -> float:
        """Physics time in seconds (kept across context changes)."""
        return float(self._data.time)

    @property
    def agent_period(self) -> float:
        """Simulated seconds per agent step: 100 x 2.5 ms."""
        return float(self._model.opt.timestep) * SUB_STEPS * self.action_repeat

    @property
    def context(self) -> dict[str, float]:
        """The goal position in force now (a copy)."""
        return dict(self._context)

    def set_context(self, values: Mapping[str, float]) -> None:
        """Move the box now; joints, velocities and time are untouched."""
        self._context.update(validate_context(self.name, self.specs, values))
        self._model.body_pos[self._box, 0] = self._context['goal_x']
        self._model.body_pos[self._box, 1] = self._context['goal_y']
        mujoco.mj_forward(self._model, self._data)  # box pose, contacts and sites of this state

    def reset(self, seed: int | None = None) -> StepResult:
        """Start an episode from MELD's home pose (settled, at rest) under the current goal."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self._start()
        self._needs_reset = False
        return StepResult(
            state=self._observation(), reward=0.0, first=True, last=False, context=self.context
        )

    def step(self, action: np.ndarray) -> StepResult:
        """Move the peg target by the scaled action, simulate 0.25 s, pay MELD's reward."""
        if self._needs_reset:
            raise RuntimeError(f'{self.name}: call reset() before step() (episode over or new)')
        act = np.asarray(action, dtype=np.float64).reshape(-1)
        if act.shape != (3,):
            raise ValueError(f'{self.name}: action has {act.size} values, expected 3')
        model, data = self._model, self._data
        # Re-based on the measured peg, so a blocked peg does not accumulate a far-away target.
        target = data.xpos[self._peg] + ACTION_SCALE * np.clip(act, -1.0, 1.0)
        data.mocap_pos[0] = np.clip(target, _TARGET_LOW, _TARGET_HIGH)
        reward = 0.0
        for _ in range(self.action_repeat):
            mujoco.mj_step(model, data, nstep=SUB_STEPS)
            mujoco.mj_forward(model, data)  # kinematics of the new state for reward and state
            reward += peg_reward(data.site_xpos[self._tip], data.site_xpos[self._goal])
        return self._end_step(self._observation(), reward)

    def render(self, height: int = 84, width: int = 84) -> np.ndarray:
        """RGB frame from the fixed 'track' camera (arm, table and box in view)."""
        if self._renderer is None:
            self._renderer = SyncedRenderer(self._model, camera=self._camera)
        return self._renderer.render(self._model, self._data, height, width)

    def close(self) -> None:
        """Free the renderer (its GL context)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # --- inspection --------------------------------------------------------------------------

    @property
    def model(self) -> mujoco.MjModel:
        """The task's own model (read-only use: tests, inspection)."""
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        """The simulation state (read-only use)."""
        return self._data

    @property
    def peg_tip(self) -> np.ndarray:
        """World position of the peg tip (a copy)."""
        return self._data.site_xpos[self._tip].copy()

    @property
    def goal(self) -> np.ndarray:
        """World position of the floor of the hole, the reward's target (a copy)."""
        return self._data.site_xpos[self._goal].copy()

    # --- internals ---------------------------------------------------------------------------

    def _start(self) -> None:
        mujoco.mj_resetData(self._model, self._data)
        self._data.qpos[:] = self._home_qpos
        self._data.mocap_pos[0] = self._home_target
        self._data.mocap_quat[0] = self._home_quat
        mujoco.mj_forward(self._model, self._data)
        self._episode_step = 0

    def _observation(self) -> np.ndarray:
        data = self._data
        return np.concatenate([data.qpos, data.qvel, data.site_xpos[self._tip]]).astype(np.float64)
