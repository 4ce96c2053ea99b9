"""UP-OSI: psi(H) regressed on the true context, which conditions the policy during a warm-up."""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch.nn.functional as F  # noqa: N812

from zeus_ros.learning.objectives.base import LEARNED_CONTEXT_OPTIONS, PsiObjective

if TYPE_CHECKING:
    import torch

    from zeus_ros.learning.objectives.base import LossHost, ObjectiveConfig, PsiStep
    from zeus_ros.learning.spec import AgentSpec

__all__ = ['UpOsi']


class UpOsi(PsiObjective):
    """Online system identification: psi(H) -> the true context (privileged in training)."""

    name = 'up_osi'
    description = 'UP-OSI: psi(H) regressed on the true context (privileged in training)'
    options = (*LEARNED_CONTEXT_OPTIONS, 'up_osi_warmup_fraction')

    def context_dim(self, config: ObjectiveConfig, spec: AgentSpec) -> int:
        """Psi estimates the true context, so it has its size."""
        return self.true_context_dim(spec)

    @staticmethod
    def warmup_updates(config: ObjectiveConfig) -> int:
        """Updates during which the policy is conditioned on the true context."""
        return int(config.up_osi_warmup_fraction * config.num_updates)

    def uses_true_context(self, config: ObjectiveConfig, step: int) -> bool:
        """During the warm-up.

        The paper follows UP-OSI: first condition the universal policy on the true parameters,
        then on the inferred ones.
        """
        return step < self.warmup_updates(config)

    def psi_loss(self, host: LossHost, step: PsiStep, metrics: dict[str, torch.Tensor]
                 ) -> torch.Tensor:
        """MSE between psi(H_t) and the true context."""
        loss = F.mse_loss(step.psi, step.batch.context.float())
        metrics['loss/osi'] = loss
        return loss
