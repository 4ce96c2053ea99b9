"""A tiny context-dependent system that yields HistoryBatch objects without MuJoCo.

For tests and update-rate benchmarks: the dynamics s' = 0.9 s + 0.3 c W a and the reward
r = c * s'[0] both depend on a scalar context c, so a history does identify the context.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from zeus_ros.learning.batch import HistoryBatch
from zeus_ros.learning.spec import AgentSpec

__all__ = ['SyntheticSystem']


@dataclass
class SyntheticSystem:
    """Linear system with one context parameter `gain`, sampled per history window."""

    obs_dim: int = 6
    """State dimension."""
    action_dim: int = 2
    """Action dimension (actions in [-1, 1])."""
    k: int = 5
    """History length of the batches."""
    contexts: tuple[float, ...] = (0.5, 1.0, 1.5)
    """Context values to draw from."""
    partial_fraction: float = 0.3
    """Share of samples whose history is partial (front slots missing)."""
    pixels: bool = False
    """Emit (9, 84, 84) uint8 frames derived from the state instead of state vectors."""
    seed: int = 0
    """Seed of the generator."""

    def __post_init__(self) -> None:
        """Draw the fixed action matrix."""
        self.generator = torch.Generator().manual_seed(self.seed)
        self.weight = torch.randn(self.obs_dim, self.action_dim, generator=self.generator)

    def spec(self, task: str = 'Synthetic-v0') -> AgentSpec:
        """An AgentSpec for this system."""
        return AgentSpec(
            task=task, context_names=('gain',), obs_kind='pixels' if self.pixels else 'state',
            obs_shape=(9, 84, 84) if self.pixels else (self.obs_dim,),
            action_dim=self.action_dim, action_low=(-1.0,) * self.action_dim,
            action_high=(1.0,) * self.action_dim)

    def _render(self, states: torch.Tensor) -> torch.Tensor:
        """State -> a deterministic uint8 frame stack (brightness bands from the state)."""
        levels = (torch.sigmoid(states) * 255).to(torch.uint8)  # (..., D)
        idx = torch.arange(9 * 84 * 84) % states.shape[-1]
        return levels[..., idx].reshape(*states.shape[:-1], 9, 84, 84)

    def sample(self, batch_size: int, context: float | None = None) -> HistoryBatch:
        """Windows of k + 1 steps from random starts; the last step is the current transition."""
        g, b, k = self.generator, batch_size, self.k
        values = torch.tensor(self.contexts)
        if context is None:
            c = values[torch.randint(len(values), (b,), generator=g)].unsqueeze(1)
        else:
            c = torch.full((b, 1), float(context))
        states = [torch.randn(b, self.obs_dim, generator=g)]
        actions, rewards = [], []
        for _ in range(k + 1):
            a = torch.rand(b, self.action_dim, generator=g) * 2 - 1
            nxt = 0.9 * states[-1] + 0.3 * c * (a @ self.weight.T)
            actions.append(a)
            rewards.append(c * nxt[:, :1])
            states.append(nxt)
        obs = torch.stack(states)  # (k + 2, B, D)
        act, rew = torch.stack(actions), torch.stack(rewards)
        hist_mask = torch.ones(b, k, dtype=torch.bool)
        partial = torch.rand(b, generator=g) < self.partial_fraction
        missing = torch.randint(0, k + 1, (b,), generator=g) * partial
        hist_mask &= torch.arange(k).unsqueeze(0) >= missing.unsqueeze(1)
        if self.pixels:
            obs = self._render(obs)
        hist_obs = obs[:k].transpose(0, 1).clone()
        hist_next = obs[1:k + 1].transpose(0, 1).clone()
        hist_act = act[:k].transpose(0, 1).clone()
        hist_rew = rew[:k].transpose(0, 1).clone()
        for tensor in (hist_obs, hist_next, hist_act, hist_rew):
            view = tensor.view(b, k, -1)
            view[~hist_mask] = 0
        return HistoryBatch(
            obs=obs[k], action=act[k], reward=rew[k], next_obs=obs[k + 1],
            not_done=torch.ones(b, 1), hist_obs=hist_obs, hist_action=hist_act,
            hist_reward=hist_rew, hist_next_obs=hist_next, hist_mask=hist_mask, context=c)
