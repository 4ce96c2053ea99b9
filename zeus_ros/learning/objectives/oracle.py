"""The upper bounds: the true context instead of psi(H), with or without ZeUS's models."""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch
import torch.nn.functional as F  # noqa: N812

from zeus_ros.learning.objectives.base import (
    CONTEXT_OPTIONS,
    Objective,
    RepresentationLosses,
)
from zeus_ros.learning.representation import autoencoder_loss, dynamics_loss

if TYPE_CHECKING:
    from zeus_ros.learning.batch import HistoryBatch
    from zeus_ros.learning.objectives.base import LossHost

__all__ = ['Oracle', 'OracleSac']


class Oracle(Objective):
    """ZeUS's models and losses on the true context (normalised like every context).

    Same models, same losses and the same gradient paths into phi as ZeUS, with psi(H)
    replaced by the true context, so oracle - zeus isolates knowing the context from the
    architecture.
    """

    name = 'oracle'
    description = ('upper bound: ZeUS architecture and auxiliary losses, psi replaced by the '
                   'true context (normalised like every context)')
    context_source = 'true'
    models = ('transition', 'reward')
    options = (*CONTEXT_OPTIONS, 'model_hidden_dim', 'model_lr', 'dynamics_loss',
               'model_target')

    def losses(self, host: LossHost, batch: HistoryBatch, pair: HistoryBatch | None,
               metrics: dict[str, torch.Tensor]) -> RepresentationLosses:
        """Dynamics + reward on the current transition (and the autoencoder for pixels)."""
        m, cfg = host.modules, host.config
        both = m['encoder'](torch.cat([batch.obs, batch.next_obs], dim=0))
        feat, next_feat = both.split(batch.batch_size)
        context = host.policy_context(batch.context.float()).detach()
        action = host.normalize_action(batch.action)
        dyn = dynamics_loss(m['transition'](feat, action, context),
                            host.model_target(batch.obs, batch.next_obs, next_feat),
                            cfg.dynamics_loss)
        rew = F.mse_loss(m['reward'](feat, action, context), batch.reward.float())
        total = dyn + rew
        metrics['loss/dynamics'], metrics['loss/reward'] = dyn, rew
        if 'decoder' in m:
            ae = autoencoder_loss(m['decoder'], feat, batch.obs, cfg.decoder_latent_lambda)
            total = total + ae
            metrics['loss/reconstruction'] = ae
        return RepresentationLosses(total=total, context=None, next_context=None)


class OracleSac(Objective):
    """Plain SAC(-AE) on the observation and the true context."""

    name = 'oracle_sac'
    description = 'plain SAC on the observation and the true context'
    context_source = 'true'
    options = CONTEXT_OPTIONS
