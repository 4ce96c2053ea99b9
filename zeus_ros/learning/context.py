"""psi, the context encoder: encode each transition of H, aggregate the k codes, project.

Each transition (phi(o), a, r, phi(o')) goes through an MLP with a tanh output; bounding the codes
keeps `product` from overflowing and puts every operator on the same scale (with
config.context_code_norm the pre-activations are layer-normalised first, so the tanh cannot
saturate). Missing slots of a partial history (hist_mask False) are neutral for every
operator, so their content never matters, and an all-empty history (the first step of an
episode) gives a finite, defined psi.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from zeus_ros.learning.utils import mlp

__all__ = ['AGGREGATIONS', 'CONTEXT_HEADS', 'ContextEncoder', 'ContextNormalizer',
           'HistoryFeatures', 'aggregate']

AGGREGATIONS = ('sum', 'mean', 'concat', 'product', 'min', 'max')
"""Operators that combine the k per-transition encodings of psi."""
CONTEXT_HEADS = ('linear', 'mlp')
"""What maps psi's aggregated transition codes to the context (ContextEncoder)."""


@dataclass(slots=True)
class HistoryFeatures:
    """A history H in phi space, oldest transition first, missing slots at the front."""

    feat: torch.Tensor
    """(B, k, F) phi(o_j)."""
    action: torch.Tensor
    """(B, k, A) a_j, normalised to [-1, 1]."""
    reward: torch.Tensor
    """(B, k, 1) r_{j+1}."""
    next_feat: torch.Tensor
    """(B, k, F) phi(o_{j+1})."""
    mask: torch.Tensor
    """(B, k) bool, True for real transitions."""

    def shifted(self, feat: torch.Tensor, action: torch.Tensor, reward: torch.Tensor,
                next_feat: torch.Tensor) -> HistoryFeatures:
        """H_{t+1}: drop the oldest slot and append the transition (o_t, a_t, r_{t+1}, o_{t+1})."""
        def push(hist: torch.Tensor, new: torch.Tensor) -> torch.Tensor:
            return torch.cat([hist[:, 1:], new.unsqueeze(1).to(hist.dtype)], dim=1)

        real = torch.ones_like(self.mask[:, :1])
        return HistoryFeatures(
            feat=push(self.feat, feat), action=push(self.action, action),
            reward=push(self.reward, reward), next_feat=push(self.next_feat, next_feat),
            mask=torch.cat([self.mask[:, 1:], real], dim=1))

    def detach(self) -> HistoryFeatures:
        """Same history without gradient."""
        return HistoryFeatures(self.feat.detach(), self.action, self.reward,
                               self.next_feat.detach(), self.mask)


def aggregate(codes: torch.Tensor, mask: torch.Tensor, operator: str) -> torch.Tensor:
    """Combine (B, k, E) transition codes over the k axis, ignoring slots where mask is False.

    Args:
        codes: per-transition codes, (B, k, E).
        mask: (B, k) bool, True where the slot holds a real transition.
        operator: one of AGGREGATIONS.

    Returns:
        (B, E), or (B, k * E) for 'concat'. Empty histories give zeros, except 'product' which
        gives ones (its neutral element).
    """
    if codes.dim() != 3 or mask.shape != codes.shape[:2]:
        raise ValueError(f'codes must be (B, k, E) and mask (B, k); got {tuple(codes.shape)} '
                         f'and {tuple(mask.shape)}')
    keep = mask.bool().unsqueeze(-1)
    if operator == 'sum':
        return torch.where(keep, codes, torch.zeros_like(codes)).sum(1)
    if operator == 'mean':
        total = torch.where(keep, codes, torch.zeros_like(codes)).sum(1)
        count = keep.sum(1).clamp(min=1).to(codes.dtype)
        return total / count
    if operator == 'concat':
        return torch.where(keep, codes, torch.zeros_like(codes)).flatten(1)
    if operator == 'product':
        return torch.where(keep, codes, torch.ones_like(codes)).prod(1)
    if operator in ('min', 'max'):
        fill = torch.full_like(codes, float('inf') if operator == 'min' else float('-inf'))
        filled = torch.where(keep, codes, fill)
        reduced = filled.amin(1) if operator == 'min' else filled.amax(1)
        any_real = keep.any(1)
        return torch.where(any_real, reduced, torch.zeros_like(reduced))
    raise ValueError(f'aggregation must be one of {", ".join(AGGREGATIONS)}, got {operator!r}')


class ContextEncoder(nn.Module):
    """psi(H): k transitions in phi space -> a context vector of `context_dim`."""

    def __init__(self, feature_dim: int, action_dim: int, k: int, context_dim: int,
                 aggregation: str = 'mean', transition_dim: int = 64,
                 hidden_dim: int = 128, head: str = 'linear', code_norm: bool = False) -> None:
        super().__init__()
        if aggregation not in AGGREGATIONS:
            raise ValueError(f'aggregation must be one of {", ".join(AGGREGATIONS)}, '
                             f'got {aggregation!r}')
        if head not in CONTEXT_HEADS:
            raise ValueError(f'head must be one of {", ".join(CONTEXT_HEADS)}, got {head!r}')
        self.k = k
        self.aggregation = aggregation
        self.context_dim = context_dim
        in_dim = 2 * feature_dim + action_dim + 1
        self.transition = mlp(in_dim, (hidden_dim, hidden_dim), transition_dim)
        # code_norm: unit-scale pre-activations, so the tanh cannot saturate (config.py)
        self.code_norm = (nn.LayerNorm(transition_dim, elementwise_affine=False) if code_norm
                          else nn.Identity())
        aggregated = transition_dim * (k if aggregation == 'concat' else 1)
        # 'linear': psi is a linear map of the aggregate (the paper's reading). 'mlp': Deep Sets'
        # rho, a nonlinear function of it, which can combine transitions (e.g. keep the target
        # speed consistent with every |v - target| seen) where a linear map can only average what
        # each transition says on its own.
        self.head = (nn.Linear(aggregated, context_dim) if head == 'linear'
                     else mlp(aggregated, (hidden_dim, hidden_dim), context_dim))

    def forward(self, history: HistoryFeatures) -> torch.Tensor:
        """Encode a history in phi space into (B, context_dim)."""
        return self.pool(self.codes(history), history.mask)

    def codes(self, history: HistoryFeatures) -> torch.Tensor:
        """(B, k, E) per-transition codes: kept by callers that also need psi(H_{t+1})."""
        if history.feat.shape[1] != self.k:
            raise ValueError(f'history length {history.feat.shape[1]} does not match k={self.k}')
        return self.encode(history.feat, history.action, history.reward, history.next_feat)

    def encode(self, feat: torch.Tensor, action: torch.Tensor, reward: torch.Tensor,
               next_feat: torch.Tensor) -> torch.Tensor:
        """Codes of transitions (..., F), (..., A), (..., 1), (..., F) -> (..., E)."""
        x = torch.cat([feat, action, reward, next_feat], dim=-1)
        return torch.tanh(self.code_norm(self.transition(x)))

    def pool(self, codes: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Aggregate (B, k, E) codes over the real slots and project: (B, context_dim)."""
        return self.head(aggregate(codes, mask, self.aggregation))

    def shifted(self, codes: torch.Tensor, mask: torch.Tensor, feat: torch.Tensor,
                action: torch.Tensor, reward: torch.Tensor, next_feat: torch.Tensor
                ) -> torch.Tensor:
        """psi(H_{t+1}) from H_t's codes: the k - 1 kept slots' codes are reused, one is new.

        Equal to psi(history.shifted(...)) (codes are per transition), for 1/k of the
        transition MLP's cost.
        """
        new = self.encode(feat, action, reward.to(feat.dtype), next_feat).unsqueeze(1)
        real = torch.ones_like(mask[:, :1])
        return self.pool(torch.cat([codes[:, 1:], new], dim=1),
                         torch.cat([mask[:, 1:], real], dim=1))


class ContextNormalizer(nn.Module):
    """Standardises a context at the actor/critic input with running batch statistics.

    One normaliser for every context source (psi or the true context): a context whose spread
    is 1e-3 next to features of order 1 is invisible to the policy, whatever method made it.
    Statistics move only in training (`update`), are saved with the weights and frozen at
    deployment; gradients pass through the (fixed) affine map.

    With `noise_scale` (context_norm 'reliability') each standardised dimension is also
    multiplied by its reliability, max(0, 1 - noise variance / total variance): the share of
    its variance that is not estimation noise. Standardising alone turns a psi that carries no
    signal into unit-size noise (it broke learning on the torso-length family); weighted by its
    reliability such a psi fades to 0 while a psi that does separate contexts is still fed at
    full scale. The noise is estimated without context labels, from psi(H_t) and
    psi(H_{t+1}) of the same episode: with a mean (or sum) over k transition codes one step
    changes psi by (c_new - c_old) / k, whose variance is 2/k times psi's own noise variance,
    so noise variance = k/2 * E[(psi(H_{t+1}) - psi(H_t))^2] (`noise_scale` = k/2). The few
    steps where the context itself switches add a small upward bias. The true context has
    no estimation noise (`noise_scale` 0: reliability 1).
    """

    mean: torch.Tensor
    """(dim,) buffer: running mean of the context."""
    var: torch.Tensor
    """(dim,) buffer: running (biased) variance."""
    count: torch.Tensor
    """() long buffer: batches seen by `update`."""
    noise_var: torch.Tensor
    """(dim,) buffer, only with `noise_scale`: running estimate of psi's noise variance."""

    def __init__(self, dim: int, momentum: float = 0.01, eps: float = 1e-10,
                 noise_scale: float | None = None) -> None:
        super().__init__()
        self.momentum = momentum
        self.eps = eps
        self.noise_scale = noise_scale
        self.register_buffer('mean', torch.zeros(dim))
        self.register_buffer('var', torch.ones(dim))
        self.register_buffer('count', torch.zeros((), dtype=torch.long))
        if noise_scale is not None:
            self.register_buffer('noise_var', torch.zeros(dim))

    @torch.no_grad()
    def update(self, context: torch.Tensor, next_context: torch.Tensor | None = None,
               same_episode: torch.Tensor | None = None) -> None:
        """Move the statistics towards those of a (B, dim) batch (the first batch sets them).

        `next_context` (B, dim): the context one step later in the same episode, rows where
        `same_episode` (B, 1) is 0 left out; used only with `noise_scale`.
        """
        mean, var = context.mean(0), context.var(0, unbiased=False)
        rate = 1.0 if int(self.count) == 0 else self.momentum
        self.mean.lerp_(mean, rate)
        self.var.lerp_(var, rate)
        if self.noise_scale is not None and next_context is not None:
            step = next_context - context
            if same_episode is not None:
                keep = same_episode.reshape(-1).bool()
                step = step[keep] if bool(keep.any()) else step
            self.noise_var.lerp_(self.noise_scale * step.pow(2).mean(0), rate)
        self.count += 1

    def reliability(self) -> torch.Tensor:
        """(dim,) share of each dimension's variance that is not noise (1 without noise_scale)."""
        if self.noise_scale is None:
            return torch.ones_like(self.var)
        return (1.0 - self.noise_var / (self.var + self.eps)).clamp(0.0, 1.0)

    def forward(self, context: torch.Tensor) -> torch.Tensor:
        """(B, dim) standardised context (weighted by its reliability with noise_scale)."""
        standard = (context - self.mean) / torch.sqrt(self.var + self.eps)
        return standard if self.noise_scale is None else standard * self.reliability()
