"""What an agent needs to know about its task: shapes, bounds, names and normalisation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ['AgentSpec']

PIXEL_SHAPE = (9, 84, 84)
"""3 stacked RGB frames, channels first."""


@dataclass(frozen=True)
class AgentSpec:
    """The task side of an agent; stored in checkpoints so nodes can rebuild the networks."""

    task: str
    """Task name, e.g. Cheetah-Bias-v0; its family file sets what 'auto' config values become."""
    context_names: tuple[str, ...]
    """Names of the true context parameters (order of `HistoryBatch.context` columns)."""
    obs_kind: str
    """'state' or 'pixels'."""
    obs_shape: tuple[int, ...]
    """(D,) for state vectors, (9, 84, 84) for stacked frames."""
    action_dim: int
    """Number of action dimensions."""
    action_low: tuple[float, ...]
    """Lower action bound per dimension."""
    action_high: tuple[float, ...]
    """Upper action bound per dimension."""
    obs_mean: tuple[float, ...] | None = None
    """State only: dataset mean used to normalise observations (None: no shift)."""
    obs_std: tuple[float, ...] | None = None
    """State only: dataset std used to normalise observations (None: no scaling)."""

    def __post_init__(self) -> None:
        """Normalise sequences to tuples of plain numbers and check consistency."""
        set_ = object.__setattr__
        set_(self, 'context_names', tuple(str(name) for name in self.context_names))
        set_(self, 'obs_shape', tuple(int(size) for size in self.obs_shape))
        set_(self, 'action_low', tuple(float(v) for v in np.ravel(self.action_low)))
        set_(self, 'action_high', tuple(float(v) for v in np.ravel(self.action_high)))
        if self.obs_kind not in ('state', 'pixels'):
            raise ValueError(f"obs_kind must be 'state' or 'pixels', got {self.obs_kind!r}")
        if self.obs_kind == 'pixels' and self.obs_shape != PIXEL_SHAPE:
            raise ValueError(f'pixel obs_shape must be {PIXEL_SHAPE}, got {self.obs_shape}')
        if self.obs_kind == 'state' and len(self.obs_shape) != 1:
            raise ValueError(f'state obs_shape must be (D,), got {self.obs_shape}')
        if int(self.action_dim) < 1:
            raise ValueError(f'action_dim must be >= 1, got {self.action_dim}')
        set_(self, 'action_dim', int(self.action_dim))
        for name in ('action_low', 'action_high'):
            if len(getattr(self, name)) != self.action_dim:
                raise ValueError(f'{name} has {len(getattr(self, name))} values, '
                                 f'expected action_dim={self.action_dim}')
        if any(lo >= hi for lo, hi in zip(self.action_low, self.action_high, strict=True)):
            raise ValueError(f'action_low {self.action_low} must be below '
                             f'action_high {self.action_high}')
        for name in ('obs_mean', 'obs_std'):
            value = getattr(self, name)
            if value is None:
                continue
            if self.obs_kind != 'state':
                raise ValueError(f'{name} applies to state observations only')
            value = tuple(float(v) for v in np.ravel(value))
            if len(value) != self.obs_shape[0]:
                raise ValueError(f'{name} has {len(value)} values, expected {self.obs_shape[0]}')
            set_(self, name, value)
        if self.obs_std is not None and min(self.obs_std) <= 0:
            raise ValueError('obs_std must be positive (clip tiny stds before building a spec)')

    @property
    def num_context_params(self) -> int:
        """Number of true context parameters."""
        return len(self.context_names)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (lists, numbers, strings) for checkpoints."""
        return {
            'task': self.task,
            'context_names': list(self.context_names),
            'obs_kind': self.obs_kind,
            'obs_shape': list(self.obs_shape),
            'action_dim': self.action_dim,
            'action_low': list(self.action_low),
            'action_high': list(self.action_high),
            'obs_mean': None if self.obs_mean is None else list(self.obs_mean),
            'obs_std': None if self.obs_std is None else list(self.obs_std),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> AgentSpec:
        """Inverse of `to_dict`."""
        return cls(**data)
