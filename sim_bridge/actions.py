"""Validate an incoming action: reject what cannot be applied, clip what is merely too large."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

__all__ = ['ActionCheck', 'ActionStatus', 'check_action', 'safe_action']


class ActionStatus(IntEnum):
    """What happened to the action of a step; equals the StepFeedback.ACTION_* constants."""

    NONE = 0
    """No action applies (the reset observation of an episode)."""
    OK = 1
    CLIPPED = 2
    """Values outside the bounds were clipped; the rest applied as sent."""
    REJECTED = 3
    """Wrong length or NaN/Inf: the safe action was applied instead."""
    TIMEOUT = 4
    """No action arrived in time (lockstep): the safe action was applied."""
    STALE = 5
    """The newest action was too old (realtime): the safe action was applied."""


@dataclass(frozen=True)
class ActionCheck:
    """The action to apply, and why it differs from what was sent (if it does)."""

    applied: np.ndarray
    status: ActionStatus
    reason: str = ''


def safe_action(low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Zero torque, moved into the bounds when zero is outside them."""
    return np.clip(np.zeros_like(low, dtype=np.float64), low, high)


def check_action(values: Sequence[float] | np.ndarray | None, low: np.ndarray,
                 high: np.ndarray) -> ActionCheck:
    """Turn what a policy sent into what the physics gets; never raises for bad input."""
    if values is None:
        return ActionCheck(safe_action(low, high), ActionStatus.TIMEOUT,
                           'no action arrived: applied the safe action')
    action = np.asarray(values, dtype=np.float64).reshape(-1)
    if action.shape != low.shape:
        return ActionCheck(safe_action(low, high), ActionStatus.REJECTED,
                           f'action has {action.size} values, the task needs {low.size}: '
                           'rejected, applied the safe action')
    bad = np.flatnonzero(~np.isfinite(action))
    if bad.size:
        return ActionCheck(safe_action(low, high), ActionStatus.REJECTED,
                           f'action holds NaN/Inf at index {bad.tolist()}: rejected, applied '
                           'the safe action')
    outside = np.flatnonzero((action < low) | (action > high))
    if outside.size:
        return ActionCheck(np.clip(action, low, high), ActionStatus.CLIPPED,
                           f'action values at index {outside.tolist()} outside '
                           f'[{low.min():g}, {high.max():g}]: clipped')
    return ActionCheck(action, ActionStatus.OK)
