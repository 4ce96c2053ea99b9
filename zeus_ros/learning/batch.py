"""The batch record that flows from the replay buffer into every learner."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch

__all__ = ['HistoryBatch']


@dataclass(slots=True)
class HistoryBatch:
    """Transitions (o_t, a_t, r_{t+1}, o_{t+1}) with the history H_t that precedes each one.

    H_t holds the last k transitions of the same episode that end at o_t, oldest first:
    (o_j, a_j, r_{j+1}, o_{j+1}) for j = t-k .. t-1. At an episode start fewer exist; the missing
    ones are zero-filled at the *front* and `hist_mask` marks them False. Observations are float
    state vectors (B, D) or uint8 stacked frames (B, 3*3, 84, 84); the learner converts.
    """

    obs: torch.Tensor
    """o_t: (B, *obs_shape)."""
    action: torch.Tensor
    """a_t: (B, A), float32 in the task's bounds."""
    reward: torch.Tensor
    """r_{t+1}: (B, 1), float32."""
    next_obs: torch.Tensor
    """o_{t+1}: (B, *obs_shape)."""
    not_done: torch.Tensor
    """(B, 1) float32: 0 where o_{t+1} is terminal (not used for time limits, which bootstrap)."""
    hist_obs: torch.Tensor
    """(B, k, *obs_shape)."""
    hist_action: torch.Tensor
    """(B, k, A)."""
    hist_reward: torch.Tensor
    """(B, k, 1)."""
    hist_next_obs: torch.Tensor
    """(B, k, *obs_shape)."""
    hist_mask: torch.Tensor
    """(B, k) bool: True where the history slot holds a real transition."""
    context: torch.Tensor
    """(B, C) float32: the true context of o_{t+1} (privileged: only up_osi/oracle/eval use it)."""
    model_obs: torch.Tensor | None = None
    """o_u of the transition the context-conditioned models (T, R) predict from psi(H_t), with
    u drawn from t .. t + model_horizon - 1 in the same episode; None: u = t (the paper)."""
    model_action: torch.Tensor | None = None
    """a_u: (B, A), with model_obs."""
    model_reward: torch.Tensor | None = None
    """r_{u+1}: (B, 1), with model_obs."""
    model_next_obs: torch.Tensor | None = None
    """o_{u+1}: (B, *obs_shape), with model_obs."""
    anchor: torch.Tensor | None = None
    """(B, 1) float32: each sample's behaviour-cloning weight (a continual round anchors the
    actor strongly where it must not forget, weakly where the context is new); None: the
    config's actor_bc_weight for every sample."""

    @property
    def batch_size(self) -> int:
        """Number of transitions in the batch."""
        return int(self.obs.shape[0])

    def to(self, device: torch.device | str) -> HistoryBatch:
        """Copy every field to `device`."""
        fields: dict[str, Any] = {name: None if getattr(self, name) is None
                                  else getattr(self, name).to(device) for name in self.__slots__}
        return HistoryBatch(**fields)

    def model_transition(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(o, a, r, o') the models predict from psi(H_t): the sampled u's, else t's."""
        if self.model_obs is None:
            return self.obs, self.action, self.reward, self.next_obs
        assert (self.model_action is not None and self.model_reward is not None
                and self.model_next_obs is not None), 'model_obs comes with all model_ fields'
        return self.model_obs, self.model_action, self.model_reward, self.model_next_obs
