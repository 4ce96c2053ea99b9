"""Finger-Spin-v0: the size of the finger's tip changes its contact geometry, mass and image.

mtenv's "finger size" edited the x half-size of the invisible touch-sensor sites only, so neither
the dynamics nor the pixels changed (REFERENCES.md 1.1). Here the context value s keeps the
paper's/mtenv's scale (s = touch-site x half-size; suite default 0.025) and drives the real
geometry:

- `fingertip` capsule radius r = 0.03 + 0.2 (s - 0.025) [m]  (suite default 0.03 at s = 0.025;
  the paper's range 0.01 .. 0.5 maps to r = 0.027 .. 0.125, which still fits between the finger
  and the spinner);
- the `touchtop` / `touchbottom` site x half-size = s (mtenv's edit, keeps the touch sensors
  comparable).

The fingertip is the only colliding geom of the distal link, so the spinner is hit by a larger
or smaller tip; mass and inertia of the distal body follow through the recompile.
"""

from __future__ import annotations

from collections.abc import Mapping

import mujoco
import numpy as np

from sim_bridge.dmc_base import DmcTask, randomize_joints
from sim_bridge.families import DeclaredSpecs

__all__ = ['FingerSpinTask', 'fingertip_radius']

_SPIN_VELOCITY = 15.0  # dm_control finger: spinning faster than this (rad/s) earns reward
_HINGE_DAMPING = 0.03  # dm_control Spin.initialize_episode
_DEFAULT_SIZE = 0.025
_DEFAULT_RADIUS = 0.03
_RADIUS_SLOPE = 0.2
_MAX_INIT_ATTEMPTS = 1000
_TOUCH_SITES = ('touchtop', 'touchbottom')


def fingertip_radius(finger_size: float) -> float:
    """Radius of the fingertip capsule for a context value (see the module docstring)."""
    return _DEFAULT_RADIUS + _RADIUS_SLOPE * (finger_size - _DEFAULT_SIZE)


class FingerSpinTask(DmcTask):
    """Finger-Spin-v0: spin the hinged body; the fingertip size changes."""

    name = 'Finger-Spin-v0'
    xml_name = 'finger.xml'
    camera = 0  # 'cam0'
    n_sub_steps = 2  # control timestep 0.02 s / physics timestep 0.01 s
    action_repeat = 2
    episode_length = 500  # 1000 control steps = the suite's 20 s
    specs = DeclaredSpecs()  # params/tasks/<name>.yaml
    model_params = ('finger_size',)

    def _prepare_spec(self, spec: mujoco.MjSpec) -> None:
        # What the suite's Spin task writes into the model at every reset, baked in once.
        hinge = spec.joint('hinge')
        hinge.damping = [_HINGE_DAMPING, *hinge.damping[1:]]
        for site in ('target', 'tip'):
            rgba = spec.site(site).rgba
            spec.site(site).rgba = [rgba[0], rgba[1], rgba[2], 0.0]

    def _edit_spec(self, spec: mujoco.MjSpec, context: Mapping[str, float]) -> None:
        size = context['finger_size']
        tip = spec.geom('fingertip')
        tip.size = [fingertip_radius(size), tip.size[1], tip.size[2]]
        for name in _TOUCH_SITES:
            site = spec.site(name)
            site.size = [size, site.size[1], site.size[2]]

    def _observation(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        sensor = data.sensor
        tip = sensor('tip').data[[0, 2]] - sensor('spinner').data[[0, 2]]
        touch = np.log1p([sensor('touchtop').data[0], sensor('touchbottom').data[0]])
        return np.concatenate(
            [
                [sensor('proximal').data[0], sensor('distal').data[0]],
                tip,
                [
                    sensor('proximal_velocity').data[0],
                    sensor('distal_velocity').data[0],
                    sensor('hinge_velocity').data[0],
                ],
                touch,
            ]
        ).astype(np.float64)

    def _reward(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> float:
        return float(data.sensor('hinge_velocity').data[0] <= -_SPIN_VELOCITY)

    def _initialize_episode(
        self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator
    ) -> None:
        for _ in range(_MAX_INIT_ATTEMPTS):
            randomize_joints(model, data, rng, unlimited=True)
            mujoco.mj_forward(model, data)
            if data.ncon == 0:
                return
        raise RuntimeError(
            f'{self.name}: no collision-free start in {_MAX_INIT_ATTEMPTS} attempts at '
            f'finger_size={self._context["finger_size"]}; use a smaller finger_size'
        )
