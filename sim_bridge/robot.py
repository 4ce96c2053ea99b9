"""A robot declared by its robot_bridge params: observation layout, action order and limits.

The same declaration serves the live node (robot_bridge turns JointState into the observation
and actions into commands) and every tool that needs the task's shape without a simulator: the
random policy (`policy -p task:=robot.yaml`) and `zeus train --task-file robot.yaml` (action
bounds). `RobotTask` is that declaration behind the ContextualTask interface; it cannot step
in-process (there is no physics here), and says so.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any

import numpy as np

from sim_bridge.core import ContextSpec, ContextualTask, StepResult
from sim_bridge.rewards import JointObservation

__all__ = ['FIELDS', 'RobotSpec', 'RobotTask', 'joint_indices', 'parse_context', 'robot_section']

FIELDS = ('position', 'velocity', 'effort')
"""JointState fields, in the order they are laid out in the state vector."""


def _names(value: Any, key: str) -> tuple[str, ...]:
    """A list parameter of names (ROS gives [''] for 'unset'); ValueError if not strings."""
    items = [value] if isinstance(value, str) else list(value or [])
    names = tuple(str(item).strip() for item in items if str(item).strip())
    if len(set(names)) != len(names):
        raise ValueError(f'robot_bridge: parameter {key} lists a name twice: {list(names)}')
    return names


def parse_context(text: str) -> dict[str, float]:
    """'payload=0.5,friction=1' -> {'payload': 0.5, 'friction': 1.0}; ValueError if malformed."""
    out: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in text.split(','))):
        name, sep, value = item.partition('=')
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sep or not name.strip() or not math.isfinite(number):
            raise ValueError(f'robot_bridge: parameter context: {item!r} must be NAME=NUMBER '
                             "(e.g. context: 'payload_kg=0.5')")
        out[name.strip()] = number
    return out


@dataclass(frozen=True)
class RobotSpec:
    """What the robot observes and how it is commanded, validated once."""

    task: str
    joints: tuple[str, ...]
    observe: tuple[str, ...]
    extra_inputs: tuple[tuple[str, int], ...]
    action_joints: tuple[str, ...]
    action_low: np.ndarray
    action_high: np.ndarray
    context: dict[str, float]
    episode_length: int
    control_rate: float

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> RobotSpec:
        """Build from robot_bridge parameters; ValueError naming the parameter and the fix."""
        task = str(params.get('task', '')).strip()
        if not task:
            raise ValueError("robot_bridge: parameter task is required: the robot's task name, "
                             "written into every step (e.g. task: 'MyArm-v0')")
        joints = _names(params.get('joints'), 'joints')
        if not joints:
            raise ValueError('robot_bridge: parameter joints is required: the JointState names '
                             "to observe, in order (e.g. joints: ['shoulder', 'elbow'])")
        observe = _names(params.get('observe', ['position', 'velocity']), 'observe')
        bad = [name for name in observe if name not in FIELDS]
        if bad or not observe:
            raise ValueError(f'robot_bridge: parameter observe={list(observe)}: choose among '
                             f'{list(FIELDS)}')
        extras = []
        for item in _names(params.get('extra_inputs', ['']), 'extra_inputs'):
            topic, _, size = item.rpartition(':')
            if not topic or not size.isdigit() or int(size) < 1:
                raise ValueError(f'robot_bridge: parameter extra_inputs: {item!r} must be '
                                 "TOPIC:SIZE (a Float64MultiArray topic and its length, "
                                 "e.g. 'imu/linear_acceleration:3')")
            extras.append((topic, int(size)))
        action_joints = _names(params.get('action_joints'), 'action_joints')
        if not action_joints:
            raise ValueError('robot_bridge: parameter action_joints is required: the joints (or '
                             "axes) the policy's action drives, in action order")
        low = np.asarray(params.get('action_low', []), dtype=np.float64).reshape(-1)
        high = np.asarray(params.get('action_high', []), dtype=np.float64).reshape(-1)
        if low.shape != (len(action_joints),) or high.shape != low.shape \
                or not np.all(np.isfinite(low)) or not np.all(np.isfinite(high)) \
                or not np.all(low < high):
            raise ValueError(f'robot_bridge: parameters action_low / action_high need '
                             f'{len(action_joints)} finite values each (one per action joint '
                             f'{list(action_joints)}) with low < high; got {low.tolist()} / '
                             f'{high.tolist()}')
        episode_length = int(params.get('episode_length', 1000))
        rate = float(params.get('control_rate', 50.0))
        if episode_length < 1 or not rate > 0:
            raise ValueError('robot_bridge: episode_length must be >= 1 and control_rate > 0')
        return cls(task, joints, observe, tuple(extras), action_joints, low, high,
                   parse_context(str(params.get('context', ''))), episode_length, rate)

    @property
    def state_dim(self) -> int:
        """Length of the observation: each observed field of every joint, then the extras."""
        return len(self.observe) * len(self.joints) + sum(size for _, size in self.extra_inputs)

    def observation(self, joint_values: Mapping[str, Mapping[str, float]],
                    extras: Mapping[str, np.ndarray]) -> JointObservation:
        """The observation from joint values by field and name and the extra inputs by topic."""
        parts = [np.asarray([joint_values[f][j] for j in self.joints], np.float64)
                 for f in self.observe]
        parts += [np.asarray(extras[topic], np.float64).reshape(size)
                  for topic, size in self.extra_inputs]
        named = {f: {j: float(joint_values[f][j]) for j in self.joints} for f in self.observe}
        return JointObservation(state=np.concatenate(parts), extra=dict(extras), **named)


def robot_section(data: Any) -> Mapping[str, Any] | None:
    """The robot_bridge ros__parameters of a params file's content, or None if it has none."""
    if not isinstance(data, Mapping):
        return None
    for key, section in data.items():
        if str(key).rstrip('/').rsplit('/', 1)[-1] == 'robot_bridge' and \
                isinstance(section, Mapping) and isinstance(section.get('ros__parameters'),
                                                            Mapping):
            return section['ros__parameters']
    return None


class RobotTask(ContextualTask):
    """A robot's task shape for the tools (bounds, state size, context names); never steps."""

    action_repeat = 1

    def __init__(self, spec: RobotSpec, source: Path | None = None) -> None:
        self.spec = spec
        self.name = spec.task
        self.episode_length = spec.episode_length
        self._source = source
        self._context = dict(spec.context)

    def _no_physics(self) -> ValueError:
        where = f' (declared in {self._source})' if self._source else ''
        return ValueError(f'{self.name} is a robot{where}: it steps through '
                          'robot_bridge_node on the robot, not in-process (no simulator); '
                          'record it with the recorder and train on the bags')

    @property
    def context_specs(self) -> tuple[ContextSpec, ...]:
        """The declared context names (values set by the operator, any range)."""
        return tuple(ContextSpec(name, value, -math.inf, math.inf, 'declared by the operator')
                     for name, value in self.spec.context.items())

    @property
    def action_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """action_low / action_high of the params."""
        return self.spec.action_low.astype(np.float32), self.spec.action_high.astype(np.float32)

    @property
    def state_dim(self) -> int:
        """Length of the observation vector."""
        return self.spec.state_dim

    @property
    def sim_time(self) -> float:
        """No simulated clock: always 0."""
        return 0.0

    @property
    def agent_period(self) -> float:
        """One control period."""
        return 1.0 / self.spec.control_rate

    @property
    def context(self) -> dict[str, float]:
        """The declared context now."""
        return dict(self._context)

    def set_context(self, values: Mapping[str, float]) -> None:
        """Change declared values (names are fixed)."""
        unknown = sorted(set(values) - set(self._context))
        if unknown:
            raise ValueError(f'{self.name}: unknown context parameter(s) {unknown}; declared: '
                             f'{sorted(self._context)}')
        self._context.update({k: float(v) for k, v in values.items()})

    def reset(self, seed: int | None = None) -> StepResult:
        """Refused: a robot has no in-process physics."""
        raise self._no_physics()

    def step(self, action: np.ndarray) -> StepResult:
        """Refused: a robot has no in-process physics."""
        raise self._no_physics()

    def render(self, height: int = 84, width: int = 84) -> np.ndarray:
        """Refused: a robot has no in-process physics."""
        raise self._no_physics()


def joint_indices(names: Sequence[str], wanted: Sequence[str]) -> list[int]:
    """Indices of `wanted` in `names` (a message's order); KeyError lists the missing ones."""
    index = {name: i for i, name in enumerate(names)}
    missing = [name for name in wanted if name not in index]
    if missing:
        raise KeyError(missing)
    return [index[name] for name in wanted]
