"""CaDM: psi(H) trained by forward + backward dynamics prediction."""

from __future__ import annotations

from typing import TYPE_CHECKING

from zeus_ros.learning.objectives.base import LEARNED_CONTEXT_OPTIONS, PsiObjective
from zeus_ros.learning.objectives.zeus import MODEL_OPTIONS
from zeus_ros.learning.representation import dynamics_loss

if TYPE_CHECKING:
    import torch

    from zeus_ros.learning.objectives.base import LossHost, PsiStep

__all__ = ['Cadm']


class Cadm(PsiObjective):
    """Forward model T(s, a, psi) -> s' and backward model B(s', a, psi) -> s, weighted by beta."""

    name = 'cadm'
    description = 'CaDM: psi(H) trained by forward + backward dynamics'
    models = ('transition', 'backward')
    options = (*LEARNED_CONTEXT_OPTIONS, *MODEL_OPTIONS, 'cadm_beta')
    predicts_transitions = True

    def psi_loss(self, host: LossHost, step: PsiStep, metrics: dict[str, torch.Tensor]
                 ) -> torch.Tensor:
        """Forward + cadm_beta * backward dynamics loss on the model transition."""
        m, cfg, model = host.modules, host.config, step.model
        assert model is not None  # predicts_transitions
        forward = dynamics_loss(m['transition'](model.feat, model.action, step.psi),
                                model.target, cfg.dynamics_loss)
        backward = dynamics_loss(m['backward'](model.next_feat, model.action, step.psi),
                                 host.model_target(model.next_obs, model.obs, model.feat),
                                 cfg.dynamics_loss)
        metrics['loss/dynamics'], metrics['loss/backward_dynamics'] = forward, backward
        return forward + cfg.cadm_beta * backward
