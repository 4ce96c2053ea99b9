"""The loss terms the objectives combine: dynamics, eq. 1's context loss, SAC-AE, consistency.

Pure functions of tensors and modules; which method adds which term, with which weight, is its
objective (learning/objectives/), and the agent steps the optimizers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
import torch.nn.functional as F  # noqa: N812

from zeus_ros.learning.models import (
    Gaussian,
    RewardModel,
    TransitionModel,
    gaussian_nll,
    w2_diagonal_gaussians,
)
from zeus_ros.learning.utils import safe_norm

if TYPE_CHECKING:
    from torch import nn

__all__ = [
    'ContextLoss',
    'autoencoder_loss',
    'consistency_loss',
    'context_loss',
    'dynamics_loss',
]


@dataclass(slots=True)
class ContextLoss:
    """The context term of eq. 1 and the two distances it compares."""

    loss: torch.Tensor
    """MSE(||psi(H1) - psi(H2)||_2, d(c1, c2)), scalar."""
    task_distance: torch.Tensor
    """(B,) d(c1, c2) from the learned T and R (no gradient)."""
    context_distance: torch.Tensor
    """(B,) ||psi(H1) - psi(H2)||_2 (with gradient into psi)."""


def dynamics_loss(pred: Gaussian, target: torch.Tensor, kind: str) -> torch.Tensor:
    """'gaussian_nll' (fits mu and sigma) or 'mse' (mu only) against a target latent."""
    if kind == 'gaussian_nll':
        return gaussian_nll(pred, target)
    return F.mse_loss(pred.mu, target)


def context_loss(transition: TransitionModel, reward: RewardModel, feat: torch.Tensor,
                 action: torch.Tensor, psi1: torch.Tensor, psi2: torch.Tensor, *,
                 use_sigma: bool = True, scale_free: bool = False,
                 bounded: bool = False,
                 at_psi1: tuple[torch.Tensor, Gaussian] | None = None) -> ContextLoss:
    """Eq. 1 context loss: distances in psi space should match d computed from T and R.

    d(c1, c2) = |R(s, a, psi1) - R(s, a, psi2)| + W2(T(s, a, psi1), T(s, a, psi2)) on the SAME
    (s, a) = (phi(o1), a1), with stopped gradients: T and R (and phi) receive nothing from here.

    Args:
        transition: T.
        reward: R.
        feat: phi(o1), (B, F).
        action: a1 in [-1, 1], (B, A).
        psi1: psi(H1), (B, C), with gradient.
        psi2: psi(H2), (B, C), with gradient.
        use_sigma: include the sigma term of W2 (False when T's sigma is not trained).
        scale_free: divide both distance vectors by their batch mean first, so the loss asks
            for the pattern of distances and psi cannot satisfy it by shrinking (d is computed
            at psi, so the paper's form is solved by psi = constant, where both sides are 0).
        bounded: with scale_free, multiply the loss by the detached mean psi distance squared:
            the same minimum, but a gradient of the size eq. 1's would have at psi's scale
            instead of 1 / (mean psi distance) times it, which outweighs the dynamics loss's
            gradient into psi whenever psi is tight.
        at_psi1: R(s, a, psi1) and T(s, a, psi1) when the caller computed them on this same
            (s, a) already (the dynamics and reward losses do): used detached, not recomputed.
    """
    with torch.no_grad():
        feat, p1, p2 = feat.detach(), psi1.detach(), psi2.detach()
        if at_psi1 is None:
            r1, t1 = reward(feat, action, p1), transition(feat, action, p1)
        else:
            r1 = at_psi1[0].detach()
            t1 = Gaussian(mu=at_psi1[1].mu.detach(), sigma=at_psi1[1].sigma.detach())
        r_gap = (r1 - reward(feat, action, p2)).abs().squeeze(-1)
        t2 = transition(feat, action, p2)
        if not use_sigma:
            t2 = Gaussian(mu=t2.mu, sigma=t1.sigma)
        task_distance = r_gap + w2_diagonal_gaussians(t1, t2)
    context_distance = safe_norm(psi1 - psi2, dim=-1)
    if scale_free:
        eps = 1e-8
        scale = context_distance.mean() + eps
        loss = F.mse_loss(context_distance / scale, task_distance / (task_distance.mean() + eps))
        if bounded:
            loss = loss * scale.detach() ** 2
    else:
        loss = F.mse_loss(context_distance, task_distance)
    return ContextLoss(loss=loss,
                       task_distance=task_distance, context_distance=context_distance)


def autoencoder_loss(decoder: nn.Module, feat: torch.Tensor, obs: torch.Tensor,
                     latent_lambda: float) -> torch.Tensor:
    """SAC-AE: reconstruct frames (centred in [-0.5, 0.5]) from phi(o), plus L2 on phi(o)."""
    target = obs.float() / 255.0 - 0.5
    reconstruction = F.mse_loss(decoder(feat), target)
    return reconstruction + latent_lambda * 0.5 * feat.pow(2).sum(-1).mean()


def consistency_loss(psi: torch.Tensor, next_psi: torch.Tensor,
                     not_done: torch.Tensor) -> torch.Tensor:
    """Within-episode drift of psi relative to its spread across the batch (scale-free).

    The context is constant over long stretches of an episode, so psi(H_t) and psi(H_{t+1})
    (one transition apart, target stopped) should agree, while histories drawn at random from
    the batch (mostly other contexts) should not: mean ||psi_t - psi_{t+1}||^2 divided by
    mean ||psi_i - psi_j||^2 over random pairs. The ratio has no trivial solution in the size
    of psi; it uses no context labels.
    """
    keep = not_done.reshape(-1).bool()
    drift = (psi - next_psi.detach()).pow(2).sum(-1)
    drift = drift[keep].mean() if bool(keep.any()) else drift.mean()
    shuffled = psi.roll(1, dims=0)
    spread = (psi - shuffled).pow(2).sum(-1).mean()
    return drift / (spread + 1e-8)
