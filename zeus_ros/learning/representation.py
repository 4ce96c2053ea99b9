"""Representation losses of every method: ZeUS eq. 1, CaDM, UP-OSI and the SAC-AE decoder.

Pure functions over the agent's modules; the agent steps the optimizers. They read the agent
through `LossHost`, the few members they need, so this module sits below agent.py (which calls
it) instead of importing it back.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

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

    from zeus_ros.learning.batch import HistoryBatch
    from zeus_ros.learning.config import ZeusConfig
    from zeus_ros.learning.context import HistoryFeatures
    from zeus_ros.learning.methods import MethodSpec

__all__ = [
    'ContextLoss',
    'LossHost',
    'RepresentationLosses',
    'autoencoder_loss',
    'consistency_loss',
    'context_loss',
    'dynamics_loss',
    'representation_losses',
]


class LossHost(Protocol):
    """What the losses read of an agent (learning.agent.ZeusAgent is the one implementation)."""

    modules: dict[str, nn.Module]
    config: ZeusConfig
    method_spec: MethodSpec

    def history_features(self, hist_obs: torch.Tensor, hist_action: torch.Tensor,
                         hist_reward: torch.Tensor, hist_next_obs: torch.Tensor,
                         hist_mask: torch.Tensor, *extra_obs: torch.Tensor
                         ) -> tuple[HistoryFeatures, list[torch.Tensor]]:
        """Encode a (B, k) history and extra observations in one encoder pass."""
        ...

    def normalize_action(self, action: torch.Tensor) -> torch.Tensor:
        """Task-bound actions -> [-1, 1]."""
        ...

    def model_target(self, obs: torch.Tensor, next_obs: torch.Tensor,
                     next_feat: torch.Tensor) -> torch.Tensor:
        """What the transition model predicts for o -> o', gradient stopped."""
        ...

    def policy_context(self, context: torch.Tensor, noise: torch.Tensor | None = None
                       ) -> torch.Tensor:
        """A context as the policy sees it (normalised)."""
        ...


@dataclass(slots=True)
class ContextLoss:
    """The context term of eq. 1 and the two distances it compares."""

    loss: torch.Tensor
    """MSE(||psi(H1) - psi(H2)||_2, d(c1, c2)), scalar."""
    task_distance: torch.Tensor
    """(B,) d(c1, c2) from the learned T and R (no gradient)."""
    context_distance: torch.Tensor
    """(B,) ||psi(H1) - psi(H2)||_2 (with gradient into psi)."""


@dataclass(slots=True)
class RepresentationLosses:
    """What one representation step produced."""

    total: torch.Tensor
    """Scalar to back-propagate."""
    context: torch.Tensor | None
    """Detached psi(H_t), (B, C); None when the method has no psi."""
    next_context: torch.Tensor | None
    """Detached psi(H_{t+1}) with H_{t+1} = H_t shifted by the current transition."""


def dynamics_loss(pred: Gaussian, target: torch.Tensor, kind: str) -> torch.Tensor:
    """'gaussian_nll' (fits mu and sigma) or 'mse' (mu only) against a target latent."""
    if kind == 'gaussian_nll':
        return gaussian_nll(pred, target)
    return F.mse_loss(pred.mu, target)


def context_loss(transition: TransitionModel, reward: RewardModel, feat: torch.Tensor,
                 action: torch.Tensor, psi1: torch.Tensor, psi2: torch.Tensor, *,
                 use_sigma: bool = True, scale_free: bool = False,
                 bounded: bool = False) -> ContextLoss:
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
    """
    with torch.no_grad():
        feat, p1, p2 = feat.detach(), psi1.detach(), psi2.detach()
        r_gap = (reward(feat, action, p1) - reward(feat, action, p2)).abs().squeeze(-1)
        t1, t2 = transition(feat, action, p1), transition(feat, action, p2)
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


def representation_losses(agent: LossHost, batch: HistoryBatch, pair: HistoryBatch | None,
                          metrics: dict[str, torch.Tensor]) -> RepresentationLosses:
    """Losses of the agent's method on one batch (H1) and, for ZeUS, a pair batch (H2)."""
    m, cfg = agent.modules, agent.config
    zero = batch.reward.new_zeros(())
    objective = agent.method_spec.objective
    if agent.method_spec.context_source == 'true' and objective != 'none':
        return _true_context_losses(agent, batch, metrics)
    if 'psi' not in m:
        feat = m['encoder'](batch.obs)
        total = autoencoder_loss(m['decoder'], feat, batch.obs, cfg.decoder_latent_lambda)
        metrics['loss/reconstruction'] = total
        return RepresentationLosses(total=total, context=None, next_context=None)

    ahead = batch.model_obs is not None and objective in ('zeus', 'cadm')
    extra = (batch.model_obs, batch.model_next_obs) if ahead else ()
    history, (feat, next_feat, *model_feats) = agent.history_features(
        batch.hist_obs, batch.hist_action, batch.hist_reward, batch.hist_next_obs,
        batch.hist_mask, batch.obs, batch.next_obs, *extra)
    psi1 = m['psi'](history)
    action = agent.normalize_action(batch.action)
    target_next = next_feat.detach()  # stopped phi(o'): no gradient from the dynamics loss
    # What T and R predict from psi(H_t): the next transition, or one further on
    # (config.model_horizon).
    model_obs, model_action, model_reward, model_next_obs = batch.model_transition()
    model_feat, model_next_feat = (model_feats[0], model_feats[1]) if ahead else (feat, next_feat)
    model_next = agent.model_target(model_obs, model_next_obs, model_next_feat)
    model_action = agent.normalize_action(model_action) if ahead else action
    total = zero
    if objective == 'zeus':
        dyn = dynamics_loss(m['transition'](model_feat, model_action, psi1), model_next,
                            cfg.dynamics_loss)
        rew = F.mse_loss(m['reward'](model_feat, model_action, psi1), model_reward.float())
        total = dyn + rew
        metrics['loss/dynamics'], metrics['loss/reward'] = dyn, rew
        if pair is not None:
            pair_history, _ = agent.history_features(
                pair.hist_obs, pair.hist_action, pair.hist_reward, pair.hist_next_obs,
                pair.hist_mask)
            ctx = context_loss(m['transition'], m['reward'], feat, action, psi1,
                               m['psi'](pair_history),
                               use_sigma=cfg.dynamics_loss == 'gaussian_nll',
                               scale_free=cfg.context_loss.startswith('scale_free'),
                               bounded=cfg.context_loss == 'scale_free_bounded')
            total = total + float(cfg.alpha_psi) * ctx.loss
            metrics['loss/context'] = ctx.loss
            metrics['train/task_distance'] = ctx.task_distance.mean()
            metrics['train/context_distance'] = ctx.context_distance.mean()
    elif objective == 'cadm':
        forward = dynamics_loss(m['transition'](model_feat, model_action, psi1), model_next,
                                cfg.dynamics_loss)
        backward = dynamics_loss(m['backward'](model_next_feat, model_action, psi1),
                                 agent.model_target(model_next_obs, model_obs, model_feat),
                                 cfg.dynamics_loss)
        total = forward + cfg.cadm_beta * backward
        metrics['loss/dynamics'], metrics['loss/backward_dynamics'] = forward, backward
    elif objective == 'up_osi':
        total = F.mse_loss(psi1, batch.context.float())
        metrics['loss/osi'] = total
    if 'decoder' in m:
        ae = autoencoder_loss(m['decoder'], feat, batch.obs, cfg.decoder_latent_lambda)
        total = total + ae
        metrics['loss/reconstruction'] = ae
    with torch.no_grad():
        next_history = history.detach().shifted(feat.detach(), action, batch.reward,
                                                target_next)
        next_context = m.get('psi_target', m['psi'])(next_history)
    if cfg.context_consistency > 0:
        consistency = consistency_loss(psi1, next_context, batch.not_done)
        total = total + cfg.context_consistency * consistency
        metrics['loss/consistency'] = consistency
    return RepresentationLosses(total=total, context=psi1.detach(), next_context=next_context)


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


def _true_context_losses(agent: LossHost, batch: HistoryBatch,
                         metrics: dict[str, torch.Tensor]) -> RepresentationLosses:
    """The oracle's auxiliary losses: ZeUS's dynamics + reward models on the true context.

    Same models, same losses and the same gradient paths into phi as ZeUS, with psi(H)
    replaced by the true context (normalised like every context), so oracle - zeus isolates
    knowing the context from the architecture.
    """
    m, cfg = agent.modules, agent.config
    both = m['encoder'](torch.cat([batch.obs, batch.next_obs], dim=0))
    feat, next_feat = both.split(batch.batch_size)
    context = agent.policy_context(batch.context.float()).detach()
    action = agent.normalize_action(batch.action)
    dyn = dynamics_loss(m['transition'](feat, action, context),
                        agent.model_target(batch.obs, batch.next_obs, next_feat),
                        cfg.dynamics_loss)
    rew = F.mse_loss(m['reward'](feat, action, context), batch.reward.float())
    total = dyn + rew
    metrics['loss/dynamics'], metrics['loss/reward'] = dyn, rew
    if 'decoder' in m:
        ae = autoencoder_loss(m['decoder'], feat, batch.obs, cfg.decoder_latent_lambda)
        total = total + ae
        metrics['loss/reconstruction'] = ae
    return RepresentationLosses(total=total, context=None, next_context=None)
