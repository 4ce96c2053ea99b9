"""SAC networks on [phi(o), psi(H)]: a tanh-squashed Gaussian actor and twin critics."""

from __future__ import annotations

from dataclasses import dataclass
import math

import torch
from torch import nn

from zeus_ros.learning.utils import mlp

__all__ = ['Actor', 'Critic', 'PolicyOutput', 'PolicySample', 'QValues', 'squashed_sample']


@dataclass(slots=True)
class PolicyOutput:
    """Parameters of the pre-tanh Gaussian."""

    mu: torch.Tensor
    """(B, A) mean."""
    log_std: torch.Tensor
    """(B, A) log std, inside the configured bounds."""


@dataclass(slots=True)
class PolicySample:
    """A tanh-squashed action in [-1, 1] and its log-probability."""

    action: torch.Tensor
    """(B, A) action in [-1, 1]."""
    log_prob: torch.Tensor
    """(B, 1) log pi(a|s) including the tanh correction."""


class Actor(nn.Module):
    """MLP policy with 2 hidden layers; log std squashed into [log_std_min, log_std_max]."""

    def __init__(self, in_dim: int, action_dim: int, hidden_dim: int, log_std_min: float,
                 log_std_max: float) -> None:
        super().__init__()
        self.net = mlp(in_dim, (hidden_dim, hidden_dim), 2 * action_dim)
        self.log_std_min = log_std_min
        self.log_std_max = log_std_max

    def forward(self, x: torch.Tensor) -> PolicyOutput:
        """Gaussian parameters for input [phi(o), psi(H)]."""
        mu, log_std = self.net(x).chunk(2, dim=-1)
        log_std = torch.tanh(log_std)
        log_std = self.log_std_min + 0.5 * (self.log_std_max - self.log_std_min) * (log_std + 1)
        return PolicyOutput(mu=mu, log_std=log_std)


def squashed_sample(out: PolicyOutput, deterministic: bool = False) -> PolicySample:
    """Sample (or take the mode of) the squashed Gaussian (SAC paper, appendix C)."""
    std = out.log_std.exp()
    pre_tanh = out.mu if deterministic else out.mu + torch.randn_like(out.mu) * std
    noise = (pre_tanh - out.mu) / std
    log_prob = (-0.5 * noise.pow(2) - out.log_std).sum(-1, keepdim=True)
    log_prob = log_prob - 0.5 * math.log(2 * math.pi) * out.mu.shape[-1]
    action = torch.tanh(pre_tanh)
    # log(1 - tanh(x)^2) computed stably as 2 * (log 2 - x - softplus(-2x)).
    correction = 2 * (math.log(2.0) - pre_tanh - nn.functional.softplus(-2 * pre_tanh))
    return PolicySample(action=action, log_prob=log_prob - correction.sum(-1, keepdim=True))


@dataclass(slots=True)
class QValues:
    """Both Q estimates of the twin critic."""

    q1: torch.Tensor
    """(B, 1) first head."""
    q2: torch.Tensor
    """(B, 1) second head."""

    def min(self) -> torch.Tensor:
        """Clipped double-Q estimate, (B, 1)."""
        return torch.min(self.q1, self.q2)


class Critic(nn.Module):
    """Twin Q heads on [phi(o), psi(H), a] (clipped double Q)."""

    def __init__(self, in_dim: int, action_dim: int, hidden_dim: int) -> None:
        super().__init__()
        self.q1 = mlp(in_dim + action_dim, (hidden_dim, hidden_dim), 1)
        self.q2 = mlp(in_dim + action_dim, (hidden_dim, hidden_dim), 1)

    def forward(self, x: torch.Tensor, action: torch.Tensor) -> QValues:
        """Both Q estimates, each (B, 1)."""
        xa = torch.cat([x, action], dim=-1)
        return QValues(q1=self.q1(xa), q2=self.q2(xa))
