"""Cheetah tasks: torso length (v0), target velocity (v1), motor strength and bias (ours).

Torso length L is the half-length of the torso capsule (dm_control default 0.5, fromto
"-L 0 0 L 0 0"). The legs and head are attached to the torso ends and move with them
(bthigh at x=-L, fthigh at x=+L, head at x=L+0.1): a longer cheetah, not a longer rod with legs in
the middle (mtenv only stretched the capsule). Mass follows the geometry: the suite's
`settotalmass="14"` (which would keep the total at 14 kg and make the legs lighter as the torso
grows) is replaced by the equivalent constant density, so the default model has exactly the
suite's masses and a longer torso is heavier.
"""

from __future__ import annotations

from collections.abc import Mapping
import functools

from dm_control.utils import rewards
import mujoco
import numpy as np

from sim_bridge.dmc_base import DmcTask, randomize_joints
from sim_bridge.families import DeclaredSpecs
from sim_bridge.model_edit import load_suite_spec

__all__ = ['CheetahBiasTask', 'CheetahMotorTask', 'CheetahRunTask', 'CheetahVelocityTask']

_TOTAL_MASS = 14.0  # the suite's settotalmass
_RUN_SPEED = 10.0  # dm_control cheetah: speed above which the run reward is 1
_SETTLE_STEPS = 200  # dm_control cheetah: physics steps to settle before an episode
_CTRL_COST = 0.01  # Cheetah-Run-v1 control cost weight (MELD cheetah_vel)
_MOTOR_TARGET_SPEED = 2.0  # Cheetah-Motor-v0 and -Bias-v0: the forward speed to match [m/s]
_HEAD_OFFSET = 0.1  # head capsule centre is 0.1 beyond the torso end (0.6 for L=0.5)

_OBS_START = 1  # observation skips rootx (translation invariance), as the suite


@functools.cache
def _suite_density() -> float:
    """Geom density that reproduces `settotalmass=14` for the default cheetah."""
    spec = load_suite_spec('cheetah.xml', light_textures=True)
    spec.compiler.settotalmass = -1
    model = spec.compile()
    return 1000.0 * _TOTAL_MASS / float(model.body_mass.sum())


class _Cheetah(DmcTask):
    """Suite cheetah with explicit density and torso-length editing."""

    xml_name = 'cheetah.xml'
    camera = 0  # 'side', tracking the centre of mass (SAC-AE)
    n_sub_steps = 1  # control timestep == physics timestep (0.01 s)
    action_repeat = 4

    def _prepare_spec(self, spec: mujoco.MjSpec) -> None:
        spec.compiler.settotalmass = -1
        density = _suite_density()
        for geom in spec.geoms:
            geom.density = density

    def _edit_spec(self, spec: mujoco.MjSpec, context: Mapping[str, float]) -> None:
        length = context.get('torso_length', 0.5)
        spec.geom('torso').fromto = [-length, 0.0, 0.0, length, 0.0, 0.0]
        spec.body('bthigh').pos = [-length, 0.0, 0.0]
        spec.body('fthigh').pos = [length, 0.0, 0.0]
        head = spec.geom('head')
        head.pos = [length + _HEAD_OFFSET, 0.0, head.pos[2]]

    def _observation(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        return np.concatenate([data.qpos[_OBS_START:], data.qvel]).astype(np.float64)

    @staticmethod
    def _speed(data: mujoco.MjData) -> float:
        return float(data.sensor('torso_subtreelinvel').data[0])

    def _initialize_episode(
        self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator
    ) -> None:
        randomize_joints(model, data, rng, unlimited=False)
        mujoco.mj_step(model, data, nstep=_SETTLE_STEPS)
        data.time = 0.0


class CheetahRunTask(_Cheetah):
    """Cheetah-Run-v0: run forward; the torso length changes the body."""

    name = 'Cheetah-Run-v0'
    episode_length = 500
    specs = DeclaredSpecs()  # params/tasks/<name>.yaml
    model_params = ('torso_length',)

    def _reward(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> float:
        return float(
            rewards.tolerance(
                self._speed(data),
                bounds=(_RUN_SPEED, float('inf')),
                margin=_RUN_SPEED,
                value_at_margin=0,
                sigmoid='linear',
            )
        )


class CheetahVelocityTask(_Cheetah):
    """Cheetah-Run-v1: match a target forward speed; the context only changes the reward."""

    name = 'Cheetah-Run-v1'
    episode_length = 40
    specs = DeclaredSpecs()  # params/tasks/<name>.yaml
    model_params = ()

    def _reward(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> float:
        target = self._context['target_velocity']
        return -abs(self._speed(data) - target) - _CTRL_COST * float(np.dot(action, action))


class CheetahMotorTask(_Cheetah):
    """Cheetah-Motor-v0: match 2 m/s while the motors' strength changes (dynamics only).

    `motor_gain` scales every actuator's gear: the torque one unit of command produces, as a
    battery sags or a motor wears. Our addition, not a paper family: Cheetah-Run-v0's torso length
    offers a policy nothing to gain from knowing it at our budgets (docs/results.md), while here
    the same command does a different thing in each context, so acting well from the first step
    of an episode needs the context. Speed tracking and 40-step episodes as Cheetah-Run-v1, with
    the target fixed, so the context changes only the dynamics.
    """

    name = 'Cheetah-Motor-v0'
    episode_length = 40
    specs = DeclaredSpecs()  # params/tasks/<name>.yaml
    model_params = ('motor_gain',)

    def _prepare_spec(self, spec: mujoco.MjSpec) -> None:
        super()._prepare_spec(spec)
        self._suite_gears = [np.array(actuator.gear, dtype=np.float64)
                             for actuator in spec.actuators]

    def _edit_spec(self, spec: mujoco.MjSpec, context: Mapping[str, float]) -> None:
        super()._edit_spec(spec, context)
        gain = context.get('motor_gain', 1.0)
        for actuator, gear in zip(spec.actuators, self._suite_gears, strict=True):
            actuator.gear = gear * gain

    def _reward(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> float:
        return _track_target_speed(self._speed(data), action)


class CheetahBiasTask(_Cheetah):
    """Cheetah-Bias-v0: match 2 m/s while every motor adds a constant torque (dynamics only).

    `motor_bias` is a torque each motor produces whatever it is commanded, in units of its full
    command (0.3: 30% of its peak torque, added to what the policy asks for), as a motor driver
    whose zero has drifted or a spring preload would. Our addition, not a paper family: where
    Cheetah-Motor-v0 scales what a command does (a policy can partly ignore it by pushing hard),
    here the command that does the right thing is shifted by the bias itself, so the best action
    depends on the context by construction, as Cheetah-Run-v1's does on its target; and the bias
    shows in every transition, even at rest. Episodes start from the pose the suite's cheetah
    settles in (the bias held off while settling), so the context is read from transitions, not
    from the first observation. Reward and episodes as Cheetah-Motor-v0.
    """

    name = 'Cheetah-Bias-v0'
    episode_length = 40
    specs = DeclaredSpecs()  # params/tasks/<name>.yaml
    model_params = ('motor_bias',)

    def _edit_spec(self, spec: mujoco.MjSpec, context: Mapping[str, float]) -> None:
        super()._edit_spec(spec, context)
        bias = context.get('motor_bias', 0.0)
        for actuator in spec.actuators:  # force = gain * ctrl + biasprm[0] (affine, no gain terms)
            actuator.biastype = mujoco.mjtBias.mjBIAS_AFFINE
            actuator.biasprm[0] = bias

    def _initialize_episode(
        self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator
    ) -> None:
        """Settle as the suite does, the bias held off: every context starts from the same pose.

        Otherwise the settled pose would give the bias away before the first transition.
        """
        data.ctrl[:] = -model.actuator_biasprm[:, 0]
        super()._initialize_episode(model, data, rng)
        data.ctrl[:] = 0.0

    def _reward(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> float:
        return _track_target_speed(self._speed(data), action)


def _track_target_speed(speed: float, action: np.ndarray) -> float:
    """Cheetah-Run-v1's reward with the target fixed at 2 m/s (the dynamics families)."""
    return -abs(speed - _MOTOR_TARGET_SPEED) - _CTRL_COST * float(np.dot(action, action))
