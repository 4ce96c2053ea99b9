"""Walker tasks: Walker-Walk-v0 (ground friction) and Walker-Walk-v1 (foot length).

Friction: MuJoCo combines the friction of two touching geoms with max() unless one has a higher
`priority`, so editing only the floor could never make the contact more slippery than the
walker's own 0.7. The floor gets priority 1 and its sliding friction is the context: it alone
sets the walker-ground friction (the only contacts in this model; the walker's geoms do not
collide with each other). mtenv edited the default geom class (every geom) to the same effect.

Foot length: the half-length of BOTH foot capsules (mtenv changed the left foot only, which makes
the walker asymmetric). The capsules stay centred on the foot bodies, as in mtenv; mass and
inertia follow through the recompile.
"""

from __future__ import annotations

from collections.abc import Mapping

from dm_control.utils import rewards
import mujoco
import numpy as np

from sim_bridge.dmc_base import DmcTask, randomize_joints
from sim_bridge.families import DeclaredSpecs
from sim_bridge.rewards import JointObservation

__all__ = ['WalkerFootTask', 'WalkerFrictionTask', 'walk_reward']

_STAND_HEIGHT = 1.2  # dm_control walker
_WALK_SPEED = 1.0  # dm_control walker walk
_XX, _XZ, _ZZ = 0, 2, 8  # indices into a row-major 3x3 xmat
_FEET = ('left_foot', 'right_foot')


def _walk(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    """The suite's walk reward: standing (height, upright) x (5 moving + 1) / 6."""
    torso = model.body('torso').id
    standing = rewards.tolerance(
        data.xpos[torso, 2], bounds=(_STAND_HEIGHT, float('inf')), margin=_STAND_HEIGHT / 2
    )
    upright = (1 + data.xmat[torso, _ZZ]) / 2
    stand_reward = (3 * standing + upright) / 4
    move_reward = rewards.tolerance(
        data.sensor('torso_subtreelinvel').data[0],
        bounds=(_WALK_SPEED, float('inf')),
        margin=_WALK_SPEED / 2,
        value_at_margin=0.5,
        sigmoid='linear',
    )
    return float(stand_reward * (5 * move_reward + 1) / 6)


def walk_reward(obs: JointObservation, action: np.ndarray | None,
                prev_obs: JointObservation | None) -> float:
    """The walk reward as a task-file reward (`reward: sim_bridge.walker:walk_reward`)."""
    return _walk(obs.model, obs.data)


class _Walker(DmcTask):
    """Suite planar walker, walk task (reward and observation as dm_control)."""

    xml_name = 'walker.xml'
    camera = 0  # 'side', tracking the centre of mass (SAC-AE)
    n_sub_steps = 10  # control timestep 0.025 s / physics timestep 0.0025 s
    action_repeat = 2
    episode_length = 500  # 1000 control steps = the suite's 25 s

    def _observation(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        orientations = data.xmat[1:][:, [_XX, _XZ]].ravel()
        height = data.xpos[model.body('torso').id, 2]
        return np.concatenate([orientations, [height], data.qvel]).astype(np.float64)

    def _reward(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> float:
        return _walk(model, data)

    def _initialize_episode(
        self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator
    ) -> None:
        randomize_joints(model, data, rng, unlimited=True)


class WalkerFrictionTask(_Walker):
    """Walker-Walk-v0: the sliding friction between the walker and the ground changes."""

    name = 'Walker-Walk-v0'
    specs = DeclaredSpecs()  # params/tasks/<name>.yaml
    model_params = ('friction',)

    def _prepare_spec(self, spec: mujoco.MjSpec) -> None:
        spec.geom('floor').priority = 1

    def _edit_spec(self, spec: mujoco.MjSpec, context: Mapping[str, float]) -> None:
        floor = spec.geom('floor')
        floor.friction = [context['friction'], floor.friction[1], floor.friction[2]]


class WalkerFootTask(_Walker):
    """Walker-Walk-v1: the length of both feet changes."""

    name = 'Walker-Walk-v1'
    specs = DeclaredSpecs()  # params/tasks/<name>.yaml
    model_params = ('foot_length',)

    def _edit_spec(self, spec: mujoco.MjSpec, context: Mapping[str, float]) -> None:
        for name in _FEET:
            geom = spec.geom(name)
            geom.size = [geom.size[0], context['foot_length'], geom.size[2]]
