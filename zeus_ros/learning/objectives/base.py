"""What a training objective is: the models it needs, where its context comes from, its losses.

A method is one Objective (objectives/<method>.py) in the registry (learning/methods.py). The
agent builds what the objective declares and asks it, never the method's name, how to train:
whether it needs a pair batch, when it conditions on the true context, what its representation
losses are. The objectives read the agent through `LossHost` (the few members they need), so
this package sits below agent.py instead of importing it back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, cast

import torch

from zeus_ros.learning.representation import autoencoder_loss, consistency_loss

if TYPE_CHECKING:
    from torch import nn

    from zeus_ros.learning.batch import HistoryBatch
    from zeus_ros.learning.context import ContextEncoder, HistoryFeatures
    from zeus_ros.learning.spec import AgentSpec

__all__ = [
    'CONTEXT_OPTIONS',
    'LEARNED_CONTEXT_OPTIONS',
    'LossHost',
    'ModelTransition',
    'Objective',
    'ObjectiveConfig',
    'PsiObjective',
    'PsiStep',
    'RepresentationLosses',
]

CONTEXT_OPTIONS = ('context_norm', 'context_norm_momentum', 'context_input_init',
                   'context_noise', 'context_noise_steps')
"""Options read by every method whose policy sees a context (learned or true)."""

LEARNED_CONTEXT_OPTIONS = (*CONTEXT_OPTIONS, 'k', 'aggregation', 'transition_dim',
                           'context_hidden_dim', 'context_head', 'context_code_norm',
                           'context_lr', 'critic_context_grad', 'context_target_tau',
                           'context_consistency')
"""Options read by every method whose context is psi(H)."""


class ObjectiveConfig(Protocol):
    """The training config as objectives read it (learning.config.ZeusConfig).

    A protocol, not the class: config.py checks method names against the registry above
    these modules, so they cannot import it back.
    """

    @property
    def num_updates(self) -> int:
        """Length of the run (UP-OSI's warm-up is a fraction of it)."""
        ...

    @property
    def alpha_psi(self) -> float | str:
        """Weight of eq. 1's context loss (resolved: a float)."""
        ...

    @property
    def context_dim(self) -> int:
        """Size of psi's code."""
        ...

    @property
    def context_loss(self) -> str:
        """Form of eq. 1's context loss."""
        ...

    @property
    def dynamics_loss(self) -> str:
        """'gaussian_nll' or 'mse'."""
        ...

    @property
    def cadm_beta(self) -> float:
        """Weight of CaDM's backward dynamics loss."""
        ...

    @property
    def up_osi_warmup_fraction(self) -> float:
        """Share of the updates UP-OSI conditions on the true context."""
        ...

    @property
    def context_consistency(self) -> float:
        """Weight of the consistency term on psi."""
        ...

    @property
    def decoder_latent_lambda(self) -> float:
        """L2 weight on phi(o) in the SAC-AE loss."""
        ...


class LossHost(Protocol):
    """What the objectives read of an agent (learning.agent.ZeusAgent implements it)."""

    modules: dict[str, nn.Module]

    @property
    def config(self) -> ObjectiveConfig:
        """The agent's (resolved) training config."""
        ...

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
class RepresentationLosses:
    """What one representation step produced."""

    total: torch.Tensor
    """Scalar to back-propagate."""
    context: torch.Tensor | None
    """Detached psi(H_t), (B, C); None when the method has no psi."""
    next_context: torch.Tensor | None
    """Detached psi(H_{t+1}) with H_{t+1} = H_t shifted by the current transition."""


@dataclass(slots=True)
class ModelTransition:
    """The transition T and R predict from psi(H_t): the current one or one further on."""

    feat: torch.Tensor
    """phi(o_u), (B, F)."""
    action: torch.Tensor
    """a_u in [-1, 1], (B, A)."""
    reward: torch.Tensor
    """r_{u+1}, (B, 1)."""
    next_feat: torch.Tensor
    """phi(o_{u+1}), (B, F)."""
    obs: torch.Tensor
    """o_u."""
    next_obs: torch.Tensor
    """o_{u+1}."""
    target: torch.Tensor
    """What T predicts for o_u -> o_{u+1} (host.model_target), gradient stopped."""


@dataclass(slots=True)
class PsiStep:
    """One batch through phi and psi: what a learned-context objective's losses start from."""

    batch: HistoryBatch
    pair: HistoryBatch | None
    """The pair batch (H2) when the objective asked for one, else None."""
    feat: torch.Tensor
    """phi(o_t), (B, F), with gradient."""
    action: torch.Tensor
    """a_t in [-1, 1], (B, A)."""
    psi: torch.Tensor
    """psi(H_t), (B, C), with gradient."""
    model: ModelTransition | None
    """For objectives that predict with T and R (`predicts_transitions`), else None."""


class Objective:
    """A method: what it builds, where its context comes from, what trains its representation.

    The base is a method without a learned context: its representation step (only built when
    it has a pixel decoder) is the SAC-AE autoencoder loss.
    """

    name: ClassVar[str]
    """The method's name in configs, CLIs and tables."""
    description: ClassVar[str]
    """One line for tables and help texts."""
    context_source: ClassVar[str] = 'none'
    """'psi' (learned encoder psi(H)), 'true' (the true context, privileged) or 'none'."""
    models: ClassVar[tuple[str, ...]] = ()
    """Auxiliary models trained on the context: 'transition', 'reward', 'backward'."""
    options: ClassVar[tuple[str, ...]] = ()
    """Config options this method reads beyond those of every method (SAC, encoder,
    decoder, replay); cards print only these of the method-specific ones."""
    fixed: ClassVar[Mapping[str, Any]] = {}
    """Config values this method pins whatever the config says (resolve_config applies them)."""

    def reads(self, option: str) -> bool:
        """Whether this method reads the method-specific config option `option`."""
        return option in self.options

    def needs_pair(self, config: ObjectiveConfig) -> bool:
        """Whether an update needs a second, independent batch (H2). Default: no."""
        return False

    def context_dim(self, config: ObjectiveConfig, spec: AgentSpec) -> int:
        """Size of the context the policy sees: psi's code, the true context or nothing."""
        if self.context_source == 'none':
            return 0
        if self.context_source == 'true':
            return self.true_context_dim(spec)
        return config.context_dim

    def true_context_dim(self, spec: AgentSpec) -> int:
        """The number of named context parameters (ValueError when the task has none)."""
        if spec.num_context_params == 0:
            raise ValueError(f'method {self.name!r} needs named context parameters')
        return spec.num_context_params

    def uses_true_context(self, config: ObjectiveConfig, step: int) -> bool:
        """Whether the policy sees the true context at this update (collectors too)."""
        return self.context_source == 'true'

    def losses(self, host: LossHost, batch: HistoryBatch, pair: HistoryBatch | None,
               metrics: dict[str, torch.Tensor]) -> RepresentationLosses:
        """The representation losses of one batch: here the pixel autoencoder's alone."""
        m, cfg = host.modules, host.config
        feat = m['encoder'](batch.obs)
        total = autoencoder_loss(m['decoder'], feat, batch.obs, cfg.decoder_latent_lambda)
        metrics['loss/reconstruction'] = total
        return RepresentationLosses(total=total, context=None, next_context=None)


class PsiObjective(Objective):
    """A method that learns psi(H): the shared step around its own `psi_loss`.

    Encodes the history (and the model transition, in the same encoder pass), computes
    psi(H_t), adds the autoencoder loss for pixels and the consistency term when configured,
    and returns psi(H_t) and psi(H_{t+1}) for the policy.
    """

    context_source = 'psi'
    predicts_transitions: ClassVar[bool] = False
    """Whether psi_loss predicts transitions with T (the step then builds `PsiStep.model`)."""

    def psi_loss(self, host: LossHost, step: PsiStep, metrics: dict[str, torch.Tensor]
                 ) -> torch.Tensor:
        """The method's loss on psi(H_t) (scalar); log its parts into `metrics`."""
        raise NotImplementedError

    def losses(self, host: LossHost, batch: HistoryBatch, pair: HistoryBatch | None,
               metrics: dict[str, torch.Tensor]) -> RepresentationLosses:
        """psi_loss, plus the autoencoder (pixels) and consistency terms."""
        m, cfg = host.modules, host.config
        ahead = batch.model_obs is not None and self.predicts_transitions
        extra = (batch.model_obs, batch.model_next_obs) if ahead else ()
        history, (feat, next_feat, *model_feats) = host.history_features(
            batch.hist_obs, batch.hist_action, batch.hist_reward, batch.hist_next_obs,
            batch.hist_mask, batch.obs, batch.next_obs, *extra)
        psi_net = cast('ContextEncoder', m['psi'])
        codes = psi_net.codes(history)  # kept: psi(H_{t+1}) below reuses k - 1 of them
        psi = psi_net.pool(codes, history.mask)
        action = host.normalize_action(batch.action)
        target_next = next_feat.detach()  # stopped phi(o'): no gradient from the dynamics loss
        model = None
        if self.predicts_transitions:
            model = _model_transition(host, batch, action, (feat, next_feat), model_feats)
        total = self.psi_loss(host, PsiStep(batch, pair, feat, action, psi, model), metrics)
        if 'decoder' in m:
            ae = autoencoder_loss(m['decoder'], feat, batch.obs, cfg.decoder_latent_lambda)
            total = total + ae
            metrics['loss/reconstruction'] = ae
        with torch.no_grad():  # psi(H_{t+1}), H_{t+1} = H_t + (o_t, a_t, r, o_{t+1})
            if 'psi_target' in m:
                next_history = history.detach().shifted(feat.detach(), action, batch.reward,
                                                        target_next)
                next_context = m['psi_target'](next_history)
            else:  # the same psi: reuse H_t's codes, encode only the new transition
                next_context = psi_net.shifted(codes.detach(), history.mask, feat.detach(),
                                                action, batch.reward, target_next)
        if cfg.context_consistency > 0:
            consistency = consistency_loss(psi, next_context, batch.not_done)
            total = total + cfg.context_consistency * consistency
            metrics['loss/consistency'] = consistency
        return RepresentationLosses(total=total, context=psi.detach(), next_context=next_context)


def _model_transition(host: LossHost, batch: HistoryBatch, action: torch.Tensor,
                      current: tuple[torch.Tensor, torch.Tensor],
                      model_feats: list[torch.Tensor]) -> ModelTransition:
    """What T and R predict from psi(H_t): the next transition, or the batch's later one.

    The later one (config.model_horizon) is encoded with the history: `model_feats`.
    """
    obs, model_action, reward, next_obs = batch.model_transition()
    ahead = bool(model_feats)
    feat, next_feat = (model_feats[0], model_feats[1]) if ahead else current
    return ModelTransition(
        feat=feat, action=host.normalize_action(model_action) if ahead else action,
        reward=reward, next_feat=next_feat, obs=obs, next_obs=next_obs,
        target=host.model_target(obs, next_obs, next_feat))
