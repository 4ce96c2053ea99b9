"""A novelty-gated actor: the deployed policy at familiar contexts, an adapted one at new ones.

A continual round fine-tunes the actor on a few thousand steps recorded where the robot now
runs. However it is anchored, a fine-tuned network also moves at the contexts it was trained
for (measured on Cheetah-Bias-v0: 2,000 updates that gained +13 to +21 per episode at biases
0.6-0.9 lost 3.6-4.9 at the train bias 0.3, more than a 10 % tolerance allows). This module
keeps the deployed actor untouched and adds an adapted copy that acts only where the policy's
context is far from every training context (SPIBB's rule, Laroche et al. 2019, turned around:
keep the baseline wherever the new data does not say otherwise; the novelty is the one the
estimator's monitor reports, learning/readout.py, measured on the policy's own input):

    w = clip((d(c) - low) / (high - low), 0, 1),   d(c) = min_i |c - centroid_i| / scale
    mu = mu_base + w (mu_adapted - mu_base)   (log std alike)

With w = 0 at every familiar context, nothing learned there can be forgotten (and no gradient
reaches the adapted copy from those samples); the gate is fitted on the rehearsal recording's
per-step contexts at the train values (`fit_gate`). Plain data in, tensors out: no ROS.
"""

from __future__ import annotations

import copy

import numpy as np
import torch
from torch import nn

from zeus_ros.learning.sac import Actor, PolicyOutput

__all__ = ['GATE_QUANTILE', 'GATE_RAMP', 'GatedActor', 'fit_gate']

GATE_QUANTILE = 0.995
"""`low` is this quantile of the train contexts' own scores: 1 in 200 familiar steps may
blend in a little of the adapted actor, never all of it. Handing over earlier, at the 95th
percentile, was measured (experiments/gate_quantile.py; docs/results/continual_drift/
README.md#choosing-the-hand-over): on Cheetah-Run-v1, whose train scores have a far tail
(99.5th 5.35, 95th 2.3) that the contexts beyond its range overlap, it closed 0.67 and 1.10 of
the gap live where this closes 0.41-0.48; on Cheetah-Bias-v0 it reached train steps and
forgot (7.3 per episode offline at one train bias, 4.1 live against 3.7 allowed,
test_continual's rehearsed round -18), so it is not the default. A hand-over chosen per
round from the recording's own scores is the next step."""
GATE_RAMP = 1.5
"""`high` = GATE_RAMP x `low`: a ramp, not a switch, so the action is continuous in psi.
Measured on the zoo's Cheetah-Bias-v0 (monitor units): per-step scores at the train values
stay under 2.3 (90th percentile), beyond the range (0.6-0.9) over 3.8 (10th percentile)."""


class GatedActor(nn.Module):
    """`base` (frozen) where the context is familiar, `adapted` (trained) where it is new."""

    centroids: torch.Tensor
    scale: torch.Tensor
    low: torch.Tensor
    high: torch.Tensor

    def __init__(self, base: Actor, context_dim: int, centroids: int) -> None:
        super().__init__()
        if context_dim < 1 or centroids < 1:
            raise ValueError(f'a gated actor needs a learned context and centroids, got '
                             f'context_dim {context_dim}, {centroids} centroid(s)')
        self.base = base
        self.base.requires_grad_(False)
        self.adapted = copy.deepcopy(base)
        self.adapted.requires_grad_(True)
        self.context_dim = context_dim
        self.register_buffer('centroids', torch.zeros(centroids, context_dim))
        self.register_buffer('scale', torch.ones(()))
        self.register_buffer('low', torch.zeros(()))
        self.register_buffer('high', torch.ones(()))

    def set_gate(self, centroids: np.ndarray, scale: float, low: float, high: float) -> None:
        """Install a fitted gate (`fit_gate`)."""
        with torch.no_grad():
            self.centroids.copy_(torch.as_tensor(centroids, dtype=torch.float32))
            self.scale.fill_(float(scale))
            self.low.fill_(float(low))
            self.high.fill_(float(high))

    def weight(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 1) share of the adapted actor: 0 at familiar contexts, 1 at novel ones."""
        context = x[..., -self.context_dim:]
        distance = torch.cdist(context.reshape(-1, self.context_dim), self.centroids)
        score = distance.min(-1).values.reshape(*context.shape[:-1], 1) / self.scale
        return ((score - self.low) / (self.high - self.low).clamp_min(1e-6)).clamp(0.0, 1.0)

    def forward(self, x: torch.Tensor) -> PolicyOutput:
        """The blended Gaussian parameters for input [phi(o), c]."""
        with torch.no_grad():
            base = self.base(x)
            w = self.weight(x)
        adapted = self.adapted(x)
        return PolicyOutput(mu=base.mu + w * (adapted.mu - base.mu),
                            log_std=base.log_std + w * (adapted.log_std - base.log_std))


def fit_gate(contexts: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """(centroids, scale, low, high) from per-step policy contexts at the train values.

    `labels`: the group of each step (a train value, or a value and history length).
    `scale` is the median distance of a step to its nearest centroid, `low` the GATE_QUANTILE
    of those distances over `scale`.
    """
    contexts = np.asarray(contexts, np.float64)
    keys = np.unique(labels)
    if len(contexts) < 10 * len(keys):
        raise ValueError(f'the gate needs at least 10 steps per group, got '
                         f'{len(contexts)} for {len(keys)} group(s)')
    centroids = np.stack([contexts[labels == key].mean(0) for key in keys])
    distance = np.linalg.norm(contexts[:, None, :] - centroids[None], axis=2).min(1)
    scale = float(np.median(distance)) or 1e-6
    low = float(np.quantile(distance / scale, GATE_QUANTILE))
    return centroids, scale, low, GATE_RAMP * low
