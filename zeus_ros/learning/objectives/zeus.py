"""ZeUS: psi(H) trained by dynamics + reward prediction and eq. 1's context loss; its ablation."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, cast

import torch.nn.functional as F  # noqa: N812

from zeus_ros.learning.objectives.base import LEARNED_CONTEXT_OPTIONS, PsiObjective
from zeus_ros.learning.representation import context_loss, dynamics_loss

if TYPE_CHECKING:
    from collections.abc import Mapping
    from typing import Any

    import torch

    from zeus_ros.learning.models import RewardModel, TransitionModel
    from zeus_ros.learning.objectives.base import LossHost, ObjectiveConfig, PsiStep

__all__ = ['Zeus', 'ZeusNoContextLoss']

MODEL_OPTIONS = ('context_dim', 'model_hidden_dim', 'model_lr', 'dynamics_loss',
                 'model_horizon', 'model_target')
"""What psi(H) with context-conditioned models T and R reads (ZeUS and CaDM)."""


class Zeus(PsiObjective):
    """Dynamics + reward prediction from psi(H_t), plus alpha_psi times eq. 1's context loss."""

    name = 'zeus'
    description = 'ZeUS: psi(H) trained by dynamics + reward prediction and the context loss'
    models = ('transition', 'reward')
    options: ClassVar[tuple[str, ...]] = (*LEARNED_CONTEXT_OPTIONS, *MODEL_OPTIONS, 'alpha_psi',
                                          'context_loss')
    predicts_transitions = True

    def needs_pair(self, config: ObjectiveConfig) -> bool:
        """Eq. 1 compares psi(H1) with psi(H2): a pair batch whenever alpha_psi > 0."""
        return float(config.alpha_psi) > 0

    def psi_loss(self, host: LossHost, step: PsiStep, metrics: dict[str, torch.Tensor]
                 ) -> torch.Tensor:
        """Dynamics + reward NLL/MSE on the model transition, + alpha_psi * eq. 1 (with a pair)."""
        m, cfg, model = host.modules, host.config, step.model
        assert model is not None  # predicts_transitions
        predicted = m['transition'](model.feat, model.action, step.psi)
        predicted_reward = m['reward'](model.feat, model.action, step.psi)
        dyn = dynamics_loss(predicted, model.target, cfg.dynamics_loss)
        rew = F.mse_loss(predicted_reward, model.reward.float())
        total = dyn + rew
        metrics['loss/dynamics'], metrics['loss/reward'] = dyn, rew
        pair = step.pair
        if pair is not None:
            pair_history, _ = host.history_features(
                pair.hist_obs, pair.hist_action, pair.hist_reward, pair.hist_next_obs,
                pair.hist_mask)
            ctx = context_loss(cast('TransitionModel', m['transition']),
                               cast('RewardModel', m['reward']), step.feat, step.action, step.psi,
                               m['psi'](pair_history),
                               use_sigma=cfg.dynamics_loss == 'gaussian_nll',
                               scale_free=cfg.context_loss.startswith('scale_free'),
                               bounded=cfg.context_loss == 'scale_free_bounded',
                               # eq. 1's d is at (phi(o_t), a_t): reuse T and R there if the
                               # models predicted that transition (not a later one)
                               at_psi1=((predicted_reward, predicted) if model.feat is step.feat
                                        else None))
            total = total + float(cfg.alpha_psi) * ctx.loss
            metrics['loss/context'] = ctx.loss
            metrics['train/task_distance'] = ctx.task_distance.mean()
            metrics['train/context_distance'] = ctx.context_distance.mean()
        return total


class ZeusNoContextLoss(Zeus):
    """The ablation: ZeUS with alpha_psi pinned to 0 (dynamics + reward only, no pair batch)."""

    name = 'zeus_no_context_loss'
    description = 'ZeUS ablation: alpha_psi = 0 (dynamics + reward only)'
    options = (*LEARNED_CONTEXT_OPTIONS, *MODEL_OPTIONS)
    fixed: ClassVar[Mapping[str, Any]] = {'alpha_psi': 0.0}

    def needs_pair(self, config: ObjectiveConfig) -> bool:
        """No context loss, no pair batch."""
        return False
