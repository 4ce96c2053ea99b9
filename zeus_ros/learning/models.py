"""T and R: dynamics and reward models on (phi(o), a, psi(H)), plus the distances they give."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

__all__ = [
    'Gaussian',
    'RewardModel',
    'TransitionModel',
    'gaussian_nll',
    'w2_diagonal_gaussians',
]

SIGMA_MIN = 1e-4
SIGMA_MAX = 10.0


@dataclass(slots=True)
class Gaussian:
    """A diagonal Gaussian prediction over the next latent."""

    mu: torch.Tensor
    """(B, F) mean."""
    sigma: torch.Tensor
    """(B, F) standard deviation, in [SIGMA_MIN, SIGMA_MAX]."""


class TransitionModel(nn.Module):
    """T(phi(o), a, c) -> N(mu, sigma) over phi(o'); 1 hidden layer (paper), sigma as mtrl.

    `target_dim` (default feature_dim) is the size of what it predicts: the state vector's
    size when config.model_target is 'observation'.
    """

    def __init__(self, feature_dim: int, action_dim: int, context_dim: int,
                 hidden_dim: int = 512, target_dim: int | None = None) -> None:
        super().__init__()
        self.trunk = nn.Sequential(
            nn.Linear(feature_dim + action_dim + context_dim, hidden_dim),
            nn.LayerNorm(hidden_dim), nn.ReLU(inplace=True))
        out = feature_dim if target_dim is None else target_dim
        self.mu = nn.Linear(hidden_dim, out)
        self.sigma = nn.Linear(hidden_dim, out)

    def forward(self, feat: torch.Tensor, action: torch.Tensor,
                context: torch.Tensor) -> Gaussian:
        """Predict the distribution of the next latent (or of the state change)."""
        h = self.trunk(torch.cat([feat, action, context], dim=-1))
        sigma = SIGMA_MIN + (SIGMA_MAX - SIGMA_MIN) * torch.sigmoid(self.sigma(h))
        return Gaussian(mu=self.mu(h), sigma=sigma)


class RewardModel(nn.Module):
    """R(phi(o), a, c) -> r; Linear -> LayerNorm -> ReLU -> Linear(1) as mtrl's reward decoder."""

    def __init__(self, feature_dim: int, action_dim: int, context_dim: int,
                 hidden_dim: int = 512) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(feature_dim + action_dim + context_dim, hidden_dim),
            nn.LayerNorm(hidden_dim), nn.ReLU(inplace=True), nn.Linear(hidden_dim, 1))

    def forward(self, feat: torch.Tensor, action: torch.Tensor,
                context: torch.Tensor) -> torch.Tensor:
        """Predict r_{t+1}: (B, 1)."""
        return self.net(torch.cat([feat, action, context], dim=-1))


def gaussian_nll(pred: Gaussian, target: torch.Tensor) -> torch.Tensor:
    """Mean Gaussian negative log-likelihood without the constant (mtrl's DeepMDP loss)."""
    diff = (pred.mu - target) / pred.sigma
    return (0.5 * diff.pow(2) + torch.log(pred.sigma)).mean()


def w2_diagonal_gaussians(p: Gaussian, q: Gaussian) -> torch.Tensor:
    """Per-sample 2-Wasserstein distance between diagonal Gaussians: (B,).

    Closed form for commuting covariances: sqrt(||mu_p - mu_q||^2 + ||sigma_p - sigma_q||^2).
    """
    squared = (p.mu - q.mu).pow(2).sum(-1) + (p.sigma - q.sigma).pow(2).sum(-1)
    return squared.clamp(min=0).sqrt()
