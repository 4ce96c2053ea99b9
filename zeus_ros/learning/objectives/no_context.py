"""no_context: SAC(-AE) on the observation alone (the base objective, nothing added)."""

from __future__ import annotations

from zeus_ros.learning.objectives.base import Objective

__all__ = ['NoContext']


class NoContext(Objective):
    """No context: the policy sees phi(o) only; pixels train the SAC-AE decoder."""

    name = 'no_context'
    description = 'SAC(-AE) on the observation alone'
