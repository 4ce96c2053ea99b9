"""ScheduledEnv: the ONE step loop shared by the sim_bridge node and the in-process tools.

It owns the global step index k (every observation counts, reset observations included), the
episode index and a simulation clock that never runs backwards across resets. Before producing
observation k it applies the schedule's context for (k, episode), so `EnvStep.observation.context`
is exactly the context whose physics produced o_k. After a `last` observation the next `step()`
starts a new episode: it resets and ignores the action it was given (status NONE).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sim_bridge.actions import ActionStatus, check_action
from sim_bridge.core import ContextualTask, StepResult
from sim_bridge.schedules import Schedule

__all__ = ['EnvStep', 'ScheduledEnv']


@dataclass(frozen=True)
class EnvStep:
    """Observation k with everything the step protocol publishes alongside it."""

    step: int
    """Global step index k (0 for the first reset observation of a run)."""
    episode: int
    episode_step: int
    """Index inside the episode (0 = the reset observation)."""
    observation: StepResult
    applied_action: np.ndarray | None
    """The action really applied between o_{k-1} and o_k (None for a reset observation)."""
    status: ActionStatus
    reason: str
    sim_time: float
    """Simulated seconds since the run started (monotonic across episodes): the stamp."""
    segment: int
    """Index of the context segment; grows by one whenever the context changes."""

    def with_status(self, status: ActionStatus, reason: str = '') -> EnvStep:
        """The same step with another action status (e.g. STALE instead of TIMEOUT)."""
        return replace(self, status=status, reason=reason or self.reason)


class ScheduledEnv:
    """A task driven by a context schedule, with validated actions and a run-long clock."""

    def __init__(self, task: ContextualTask, schedule: Schedule,
                 schedule_start: tuple[int, int] = (0, 0)) -> None:
        """`schedule_start`: the schedule's (step, episode) at this run's first step.

        A collection that continues earlier ones (a loop's next round) goes on with the
        schedule where they stopped; started over, a schedule of one value per episode would
        never reach its later values when a round holds fewer episodes than it has values.
        The run's own step and episode indices start at 0 either way.
        """
        self.task = task
        self.schedule = schedule
        self.schedule_start = schedule_start
        self.step_index = -1
        self.episode = -1
        self.episode_step = 0
        self.segment = -1
        self._time_offset = 0.0
        self._context: dict[str, float] | None = None
        self._needs_reset = True
        low, high = task.action_bounds
        self._low, self._high = low.astype(np.float64), high.astype(np.float64)

    @property
    def sim_time(self) -> float:
        """Simulated seconds since the run started."""
        return self._time_offset + self.task.sim_time

    def _apply_context(self, step: int, episode: int) -> None:
        context = self.schedule.value_at(step + self.schedule_start[0],
                                         episode + self.schedule_start[1])
        if context != self._context:
            self.task.set_context(context)
            self._context = context
            self.segment += 1

    def reset(self) -> EnvStep:
        """Start the next episode under the schedule's context for its first step."""
        if self.step_index >= 0:
            self._time_offset += self.task.sim_time + self.task.agent_period
        self.step_index += 1
        self.episode += 1
        self.episode_step = 0
        self._apply_context(self.step_index, self.episode)
        result = self.task.reset()
        self._needs_reset = result.last
        return EnvStep(self.step_index, self.episode, 0, result, None, ActionStatus.NONE, '',
                       self.sim_time, self.segment)

    def end_episode(self) -> bool:
        """End the running episode now: the next step() is the next episode's reset.

        An operator's reset (sim_bridge ~/reset_episode): the pending action is not applied,
        as at a time limit. False when no episode runs yet (or it ends anyway).
        """
        if self.episode < 0 or self._needs_reset:
            return False
        self._needs_reset = True
        return True

    def step(self, action: np.ndarray | None) -> EnvStep:
        """Apply one action (None: nothing arrived) and return observation k+1."""
        if self._needs_reset:
            return self.reset()
        checked = check_action(action, self._low, self._high)
        self.step_index += 1
        self.episode_step += 1
        self._apply_context(self.step_index, self.episode)
        result = self.task.step(checked.applied)
        self._needs_reset = result.last
        return EnvStep(self.step_index, self.episode, self.episode_step, result,
                       checked.applied.astype(np.float32), checked.status, checked.reason,
                       self.sim_time, self.segment)
