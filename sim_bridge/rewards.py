"""Rewards named by a string: a few built-ins, or any `package.module:function` of the user's.

ZeUS infers its context from (o, a, r, o') transitions, so a deployed robot needs a reward at
every step too. A reward is `reward(obs, action, prev_obs) -> float`, where `obs` and `prev_obs`
are `JointObservation`s (joint values by name, extra inputs by name, the flat state vector) and
`action` is the action applied between them (None at an episode start). Built-ins:

- `velocity:JOINT` - the velocity of one joint (forward speed of a wheel or a slider);
- `tracking:J1=0.5,J2=-0.2` - minus the squared distance of the joints' positions to targets.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
import importlib
import math
from typing import Any

import numpy as np

__all__ = ['BUILTINS', 'JointObservation', 'RewardFn', 'load_reward']

BUILTINS = ('velocity', 'tracking')


@dataclass(frozen=True)
class JointObservation:
    """One observation with names: what a reward function reads."""

    state: np.ndarray
    """The flat observation vector the agent sees."""
    position: Mapping[str, float] = field(default_factory=dict)
    velocity: Mapping[str, float] = field(default_factory=dict)
    effort: Mapping[str, float] = field(default_factory=dict)
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)
    """Extra inputs (e.g. Float64MultiArray topics or sensors) by name."""
    model: Any = None
    """Simulated tasks: the mujoco.MjModel in force (None on a robot)."""
    data: Any = None
    """Simulated tasks: the mujoco.MjData after the control step (None on a robot)."""


RewardFn = Callable[[JointObservation, 'np.ndarray | None', 'JointObservation | None'], float]


def _velocity(spec: str, joints: Sequence[str], fields: Sequence[str]) -> RewardFn:
    joint = spec.strip()
    if joint not in joints:
        raise ValueError(f'reward velocity:{joint}: no joint {joint!r}; observed joints: '
                         f'{list(joints)}')
    if 'velocity' not in fields:
        raise ValueError(f"reward velocity:{joint} needs 'velocity' among the observed fields "
                         f'(observe: {list(fields)})')
    return lambda obs, _action, _prev: float(obs.velocity[joint])


def _tracking(spec: str, joints: Sequence[str], fields: Sequence[str]) -> RewardFn:
    targets: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in spec.split(','))):
        name, sep, value = item.partition('=')
        try:
            targets[name.strip()] = float(value) if sep else math.nan
        except ValueError:
            targets[name.strip()] = math.nan
        if name.strip() not in joints or not math.isfinite(targets[name.strip()]):
            raise ValueError(f'reward tracking:{spec}: {item!r} must be JOINT=NUMBER with a '
                             f'joint of {list(joints)}')
    if not targets:
        raise ValueError('reward tracking: give targets, e.g. tracking:elbow=0.5,wrist=-0.2')
    if 'position' not in fields:
        raise ValueError(f"reward tracking needs 'position' among the observed fields "
                         f'(observe: {list(fields)})')
    return lambda obs, _action, _prev: -float(
        sum((obs.position[name] - target) ** 2 for name, target in targets.items()))


def _callable(spec: str) -> RewardFn:
    module_name, _, attribute = spec.partition(':')
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise ValueError(f'reward {spec!r}: cannot import module {module_name!r} ({error}); '
                         'is it on PYTHONPATH?') from None
    function = getattr(module, attribute, None)
    if not callable(function):
        raise ValueError(f'reward {spec!r}: module {module_name} has no function {attribute!r}')
    return function


def load_reward(spec: str, joints: Sequence[str], fields: Sequence[str]) -> RewardFn:
    """The reward named by `spec`; ValueError saying what is wrong and what is allowed."""
    kind, sep, rest = spec.strip().partition(':')
    if sep and kind in BUILTINS:
        return {'velocity': _velocity, 'tracking': _tracking}[kind](rest, joints, fields)
    if sep and kind and rest and '.' not in rest:
        return _callable(spec.strip())
    raise ValueError(f'reward {spec!r}: give a built-in (velocity:JOINT, tracking:JOINT=TARGET,'
                     '...) or a function as package.module:function(obs, action, prev_obs)')
