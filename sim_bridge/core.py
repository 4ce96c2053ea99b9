"""The contract every contextual task follows, shared by the node and the in-process tools."""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ['ContextSpec', 'ContextualTask', 'StepResult']


@dataclass(frozen=True)
class ContextSpec:
    """One context parameter of a task: its name, unit and the range the task accepts."""

    name: str
    default: float
    low: float
    high: float
    doc: str = ''
    unit: str = ''
    """Physical unit of the value ('' when dimensionless); the read-outs print it."""


@dataclass(frozen=True)
class StepResult:
    """What a task returns after reset or one agent step (after the action repeat)."""

    state: np.ndarray
    """Flattened proprioceptive observation (float64)."""
    reward: float
    """Reward summed over the action repeat (0.0 on reset)."""
    first: bool
    """True for the reset observation of an episode."""
    last: bool
    """True when the episode ends with this observation (time limit)."""
    context: dict[str, float]
    """The true context in force when this observation was produced."""


class ContextualTask(abc.ABC):
    """A dm_control-style task whose context can change at any step without a reset.

    One agent step applies the action for `action_repeat` physics control steps and sums the
    reward. `set_context` keeps positions, velocities and time (no reset).
    """

    name: str
    action_repeat: int
    episode_length: int
    """Agent steps per episode (after the action repeat)."""
    _episode_step: int = 0
    _needs_reset: bool = True

    @property
    @abc.abstractmethod
    def context_specs(self) -> tuple[ContextSpec, ...]:
        """The task's context parameters, in a fixed order."""

    @property
    def context_names(self) -> tuple[str, ...]:
        """Names of the context parameters, in `context_specs` order."""
        return tuple(spec.name for spec in self.context_specs)

    @property
    @abc.abstractmethod
    def action_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper action bounds (float32 arrays of the action dimension)."""

    @property
    @abc.abstractmethod
    def state_dim(self) -> int:
        """Length of `StepResult.state`."""

    @property
    @abc.abstractmethod
    def sim_time(self) -> float:
        """Physics time of the running episode in seconds (restarts at 0 on reset)."""

    @property
    @abc.abstractmethod
    def agent_period(self) -> float:
        """Simulated seconds one agent step advances (control timestep x action repeat)."""

    @property
    @abc.abstractmethod
    def context(self) -> dict[str, float]:
        """The context in force now."""

    @abc.abstractmethod
    def set_context(self, values: Mapping[str, float]) -> None:
        """Change context parameters now, keeping the physical state; raise ValueError if bad."""

    @abc.abstractmethod
    def reset(self, seed: int | None = None) -> StepResult:
        """Start a new episode under the current context."""

    @abc.abstractmethod
    def step(self, action: np.ndarray) -> StepResult:
        """Apply one (already validated, in-bounds) action for `action_repeat` control steps."""

    @abc.abstractmethod
    def render(self, height: int = 84, width: int = 84) -> np.ndarray:
        """RGB frame (height x width x 3, uint8) from the task's tracking camera."""

    @property
    def action_dim(self) -> int:
        """Number of actuators."""
        return int(self.action_bounds[0].shape[0])

    def safe_action(self) -> np.ndarray:
        """Action applied when none usable arrived: zero torque, clipped into the bounds."""
        low, high = self.action_bounds
        return np.clip(np.zeros_like(low), low, high).astype(np.float32)

    def _end_step(self, state: np.ndarray, reward: float) -> StepResult:
        """Count one agent step and build its StepResult; the episode ends at episode_length."""
        self._episode_step += 1
        last = self._episode_step >= self.episode_length
        self._needs_reset = last
        return StepResult(state=state, reward=float(reward), first=False, last=last,
                          context=self.context)

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release renderer resources."""
