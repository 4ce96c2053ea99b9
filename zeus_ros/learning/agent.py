"""The agent: owns the networks, optimizers and target nets of every method, and updates them.

What each method builds, where its context comes from and what its representation losses are
is its objective (learning/objectives/, named in the registry methods.py); the agent asks it,
never the method's name. Who trains what (one place to read it):
- phi is trained by the critic loss (SAC-AE), by the representation losses of the method (eq. 1
  for ZeUS: gradients reach phi through phi(o_t) and through the history features), and for
  pixels by the SAC-AE autoencoder loss. Dynamics targets phi(o') are always stopped.
- psi is trained by its method's objective (ZeUS: dynamics + reward + eq. 1; CaDM: forward +
  beta * backward dynamics; UP-OSI: regression on the true context) and, with
  `critic_context_grad`, also by the critic's TD loss. The actor always sees psi detached.
- the context (psi, or the true one for the oracles) is standardised at the actor/critic input
  by one ContextNormalizer unless `context_norm: none`.
- the actor sees [phi(o), c] detached (SAC-AE/drqv2: the encoder is trained via the critic).
- T and R get no gradient from the context loss: d(c1, c2) is computed under no_grad.
- psi(H_{t+1}) for the TD target comes from psi, or from its slow copy `psi_target` when
  `context_target_tau` > 0.

The dynamics loss is the Gaussian NLL of mtrl (dynamics_loss='gaussian_nll'): its optimum in mu
is the same conditional mean that eq. 1's MSE targets, and it also fits sigma, without which the
sigma part of the W2 distance in d would be untrained noise. 'mse' fits mu only (sigma unused).
"""

from __future__ import annotations

from collections.abc import Sequence
import copy
import math
from typing import Any, cast

import numpy as np
import torch
from torch import nn
import torch.nn.functional as F  # noqa: N812

from zeus_ros.learning.augment import random_shift
from zeus_ros.learning.batch import HistoryBatch
from zeus_ros.learning.config import ZeusConfig, resolve_config
from zeus_ros.learning.context import ContextEncoder, ContextNormalizer, HistoryFeatures
from zeus_ros.learning.encoders import PixelDecoder, PixelEncoder, StateEncoder
from zeus_ros.learning.gated_actor import GatedActor
from zeus_ros.learning.methods import METHOD_REGISTRY, method_objective
from zeus_ros.learning.models import RewardModel, TransitionModel
from zeus_ros.learning.sac import Actor, Critic, squashed_sample
from zeus_ros.learning.spec import AgentSpec
from zeus_ros.learning.utils import (
    resolve_device,
    set_seed_everywhere,
    soft_update_params,
    weight_init,
)

__all__ = ['PSI_METHODS', 'ZeusAgent', 'make_agent']

PSI_METHODS = frozenset(name for name, objective in METHOD_REGISTRY.items()
                        if objective.context_source == 'psi')
"""Methods whose context comes from the learned encoder psi(H)."""


def _adam(params: Any, **kwargs: Any) -> torch.optim.Adam:
    """Adam with torch's fused kernel (same rule): 5-13% off an update on this CPU.

    benchmarks/bench_optimizers.py measures it against the per-tensor loop and foreach.
    """
    return torch.optim.Adam(params, fused=True, **kwargs)


def make_agent(config: ZeusConfig, spec: AgentSpec, *,
               device: str | torch.device | None = None) -> ZeusAgent:
    """Build a fresh agent: resolves 'auto' config values for spec.task and seeds torch."""
    if config.obs_kind != spec.obs_kind:
        raise ValueError(f'config.obs_kind={config.obs_kind!r} but the task spec has '
                         f'obs_kind={spec.obs_kind!r}')
    resolved = resolve_config(config, spec.task)
    set_seed_everywhere(resolved.seed)
    return ZeusAgent(resolved, spec, device=device)


class ZeusAgent:
    """SAC(-AE) on [phi(o), c] where c is psi(H), the true context or nothing (see `method`)."""

    def __init__(self, config: ZeusConfig, spec: AgentSpec, *,
                 device: str | torch.device | None = None, optimizers: bool = True) -> None:
        """Build the networks (and, unless `optimizers=False`, their optimizers).

        `optimizers=False` gives an agent that only acts (deployment, evaluation): no Adam
        state, and torch.optim's first use, which imports torch._dynamo, never happens.
        """
        if config.alpha_psi == 'auto' or config.adam_beta1 == 'auto':
            raise ValueError('ZeusAgent needs a resolved config: build it with make_agent()')
        self.config = config
        self.spec = spec
        self.method = config.method
        self.objective = method_objective(config.method)
        self.device = resolve_device(config.device) if device is None else torch.device(device)
        cfg, a_dim = config, spec.action_dim
        source = self.objective.context_source
        self.context_dim = self.objective.context_dim(cfg, spec)
        low = torch.tensor(spec.action_low, dtype=torch.float32)
        high = torch.tensor(spec.action_high, dtype=torch.float32)
        self._action_scale = ((high - low) / 2).to(self.device)
        self._action_bias = ((high + low) / 2).to(self.device)

        self.modules: dict[str, nn.Module] = {}
        if spec.obs_kind == 'pixels':
            encoder: nn.Module = PixelEncoder(spec.obs_shape, cfg.feature_dim,
                                              cfg.num_conv_layers, cfg.num_filters)
            self.modules['decoder'] = PixelDecoder(spec.obs_shape, cfg.feature_dim,
                                                   cfg.num_conv_layers, cfg.num_filters)
        else:
            encoder = StateEncoder(spec.obs_shape[0], cfg.feature_dim, cfg.encoder_hidden_dim,
                                   spec.obs_mean, spec.obs_std)
        self.modules['encoder'] = encoder
        if source == 'psi':
            self.modules['psi'] = ContextEncoder(
                cfg.feature_dim, a_dim, cfg.k, self.context_dim, cfg.aggregation,
                cfg.transition_dim, cfg.context_hidden_dim, cfg.context_head,
                cfg.context_code_norm)
        target_dim = spec.obs_shape[0] if cfg.model_target == 'observation' else None
        for name in self.objective.models:
            if name == 'reward':
                self.modules[name] = RewardModel(cfg.feature_dim, a_dim, self.context_dim,
                                                 cfg.model_hidden_dim)
            else:
                self.modules[name] = TransitionModel(cfg.feature_dim, a_dim, self.context_dim,
                                                     cfg.model_hidden_dim, target_dim)
        policy_in = cfg.feature_dim + self.context_dim
        actor = Actor(policy_in, a_dim, cfg.hidden_dim, cfg.actor_log_std_min,
                      cfg.actor_log_std_max)
        critic = Critic(policy_in, a_dim, cfg.hidden_dim)
        self.modules['actor'], self.modules['critic'] = actor, critic
        for module in self.modules.values():
            module.apply(weight_init)
        if cfg.actor_gate > 0:  # a continual round's candidate: learning/gated_actor.py
            self.modules['actor'] = GatedActor(actor, self.context_dim, cfg.actor_gate)
        if cfg.context_input_init == 'zero' and self.context_dim > 0:
            context_inputs = slice(cfg.feature_dim, policy_in)  # input order: [phi, psi, (a)]
            for net in (actor.net, critic.q1, critic.q2):
                with torch.no_grad():
                    cast(nn.Linear, net[0]).weight[:, context_inputs] = 0.0
        if cfg.context_norm != 'none' and self.context_dim > 0:
            noise_scale = None
            if cfg.context_norm == 'reliability':  # the true context has no estimation noise
                noise_scale = 0.0 if source == 'true' else cfg.k / 2
            self.modules['context_norm'] = ContextNormalizer(
                self.context_dim, cfg.context_norm_momentum, noise_scale=noise_scale)
        self.modules['encoder_target'] = copy.deepcopy(self.modules['encoder'])
        self.modules['critic_target'] = copy.deepcopy(self.modules['critic'])
        if 'psi' in self.modules and cfg.context_target_tau > 0:
            self.modules['psi_target'] = copy.deepcopy(self.modules['psi'])
        for name in ('encoder_target', 'critic_target', 'psi_target'):
            if name in self.modules:
                self.modules[name].requires_grad_(False)
        for module in self.modules.values():
            module.to(self.device)
        self.log_alpha = torch.tensor(math.log(cfg.init_temperature), device=self.device,
                                      requires_grad=True)
        self.target_entropy = -float(a_dim)
        self._acting_error: torch.Tensor | None = None  # context_noise_steps > 0 in act()
        # Draws the augment_shift offsets; unused (no draw at all) when augment_shift is 0.
        self._shift_rng = np.random.default_rng(cfg.seed)
        self.optimizers = self._make_optimizers() if optimizers else {}

    def _make_optimizers(self) -> dict[str, torch.optim.Optimizer]:
        """Adam per group; policy, Q and temperature use the task's beta1 (paper tables)."""
        cfg, m = self.config, self.modules
        betas = (float(cfg.adam_beta1), 0.999)
        opts: dict[str, torch.optim.Optimizer] = {
            'actor': _adam([p for p in m['actor'].parameters() if p.requires_grad],
                           lr=cfg.actor_lr, betas=betas),
            'critic': _adam(
                [*m['critic'].parameters(), *m['encoder'].parameters()], lr=cfg.critic_lr,
                betas=betas),
            'alpha': _adam([self.log_alpha], lr=cfg.alpha_lr, betas=betas),
        }
        if self.has_representation_step:
            opts['encoder'] = _adam(m['encoder'].parameters(), lr=cfg.encoder_lr)
        if 'decoder' in m:
            opts['decoder'] = _adam(m['decoder'].parameters(), lr=cfg.decoder_lr,
                                               weight_decay=cfg.decoder_weight_decay)
        if 'psi' in m:
            opts['psi'] = _adam(m['psi'].parameters(), lr=cfg.context_lr)
        models = [p for name in ('transition', 'reward', 'backward') if name in m
                  for p in m[name].parameters()]
        if models:
            opts['model'] = _adam(models, lr=cfg.model_lr)
        return opts

    def gate_actor(self, centroids: Any, scale: float, low: float, high: float) -> None:
        """Wrap the actor in a GatedActor (learning/gated_actor.py).

        It acts as now at the contexts near `centroids`; only its adapted copy trains.
        """
        if isinstance(self.modules['actor'], GatedActor):
            raise ValueError('the actor is gated already')
        gated = GatedActor(cast(Actor, self.modules['actor']), self.context_dim, len(centroids))
        gated.set_gate(centroids, scale, low, high)
        self.modules['actor'] = gated.to(self.device)
        self.config = self.config.replace(actor_gate=len(centroids))
        if self.optimizers:
            self.optimizers['actor'] = _adam(gated.adapted.parameters(), lr=self.config.actor_lr,
                                             betas=(float(self.config.adam_beta1), 0.999))

    # ------------------------------------------------------------------ properties / helpers
    @property
    def has_representation_step(self) -> bool:
        """Whether update() runs a representation step (psi, models or pixel autoencoder)."""
        return ('psi' in self.modules or 'decoder' in self.modules
                or bool(self.objective.models))

    @property
    def alpha(self) -> torch.Tensor:
        """Current SAC temperature."""
        return self.log_alpha.exp()

    def uses_true_context(self, step: int) -> bool:
        """Whether the policy is conditioned on the true context at this update (collectors too).

        The objective decides: always for the oracles, during its warm-up for UP-OSI.
        """
        return self.objective.uses_true_context(self.config, step)

    def representation_frozen(self, step: int) -> bool:
        """Whether phi, psi and models are frozen at this update (representation_frozen_from)."""
        start = self.config.representation_frozen_from
        return 0 < start <= step

    def policy_context(self, context: torch.Tensor, noise: torch.Tensor | None = None
                       ) -> torch.Tensor:
        """The context as actor and critic see it: normalised when configured, plus any noise.

        The diagnostic `context_noise` is `noise` when given (a persistent error, see
        `context_noise_steps`), else drawn fresh at this call.
        """
        norm = self.modules.get('context_norm')
        context = context if norm is None else norm(context)
        if self.config.context_noise > 0 and context.shape[-1] > 0:
            if noise is None:
                noise = self.config.context_noise * torch.randn_like(context)
            context = context + noise
        return context

    def _update_noise(self, batch_size: int) -> torch.Tensor | None:
        """One persistent context error per sample for every use in an update, or None."""
        cfg = self.config
        if cfg.context_noise <= 0 or cfg.context_noise_steps == 0 or self.context_dim == 0:
            return None
        return cfg.context_noise * torch.randn(batch_size, self.context_dim, device=self.device)

    def _acting_noise(self, shape: torch.Size) -> torch.Tensor | None:
        """The persistent context error in acting: AR(1) with time constant context_noise_steps."""
        cfg = self.config
        if cfg.context_noise <= 0 or cfg.context_noise_steps == 0 or shape[-1] == 0:
            return None
        fresh = cfg.context_noise * torch.randn(shape, device=self.device)
        previous = self._acting_error
        if previous is not None and previous.shape == fresh.shape:
            keep = math.exp(-1.0 / cfg.context_noise_steps)
            fresh = keep * previous + math.sqrt(1.0 - keep ** 2) * fresh
        self._acting_error = fresh
        return fresh

    def normalize_action(self, action: torch.Tensor) -> torch.Tensor:
        """Task-bound actions -> [-1, 1] (what every network sees)."""
        return (action.float() - self._action_bias) / self._action_scale

    def model_target(self, obs: torch.Tensor, next_obs: torch.Tensor,
                     next_feat: torch.Tensor) -> torch.Tensor:
        """What T predicts for the transition o -> o' (config.model_target), gradient stopped.

        'latent': phi(o') (next_feat); 'observation': (o' - o) / obs_std, the state change in
        the units phi's input is normalised to, so every state dimension weighs alike.
        """
        if self.config.model_target == 'observation':
            std = cast(StateEncoder, self.modules['encoder']).obs_std  # observation: states
            return ((next_obs.float() - obs.float()) / std).detach()
        return next_feat.detach()

    def history_features(self, hist_obs: torch.Tensor, hist_action: torch.Tensor,
                         hist_reward: torch.Tensor, hist_next_obs: torch.Tensor,
                         hist_mask: torch.Tensor, *extra_obs: torch.Tensor
                         ) -> tuple[HistoryFeatures, list[torch.Tensor]]:
        """Encode a (B, k) history and any extra (B, ...) observations, in one encoder pass.

        Within an episode o'_j of slot j is o_{j+1} of slot j + 1; when the batch shows that for
        every real slot, only k + 1 frames per history are encoded instead of 2k (the pixel
        encoder dominates the cost). Otherwise both are encoded as given.
        """
        b, k = hist_mask.shape
        mask = hist_mask.bool()
        inner = mask[:, :-1]
        chained = bool(torch.equal(hist_next_obs[:, :-1][inner], hist_obs[:, 1:][inner]))
        if chained:
            frames = [hist_obs.flatten(0, 1), hist_next_obs[:, -1], *extra_obs]
            n_hist = b * k + b
        else:
            frames = [hist_obs.flatten(0, 1), hist_next_obs.flatten(0, 1), *extra_obs]
            n_hist = 2 * b * k
        feats = self.modules['encoder'](torch.cat(frames, dim=0))
        feat = feats[:b * k].view(b, k, -1)
        if chained:
            # Masked slots get a neighbour's features; psi ignores them whatever they hold.
            next_feat = torch.cat([feat[:, 1:], feats[b * k:n_hist].unsqueeze(1)], dim=1)
        else:
            next_feat = feats[b * k:n_hist].view(b, k, -1)
        history = HistoryFeatures(feat=feat, action=self.normalize_action(hist_action),
                                  reward=hist_reward.float(), next_feat=next_feat, mask=mask)
        return history, list(feats[n_hist:].split(b)) if extra_obs else []

    def _check_batch(self, batch: HistoryBatch, name: str) -> None:
        """Clear errors for batches that do not fit this agent."""
        spec, k = self.spec, self.config.k
        b = batch.batch_size
        expected = {
            'obs': (b, *spec.obs_shape), 'next_obs': (b, *spec.obs_shape),
            'action': (b, spec.action_dim), 'reward': (b, 1), 'not_done': (b, 1),
            'hist_obs': (b, k, *spec.obs_shape), 'hist_next_obs': (b, k, *spec.obs_shape),
            'hist_action': (b, k, spec.action_dim), 'hist_reward': (b, k, 1),
            'hist_mask': (b, k), 'context': (b, spec.num_context_params)}
        for field, shape in expected.items():
            found = tuple(getattr(batch, field).shape)
            if found != shape:
                raise ValueError(f'{name}.{field} has shape {found}, expected {shape} '
                                 f'(task {spec.task}, k={k})')

    def augment(self, batch: HistoryBatch) -> HistoryBatch:
        """The batch with its frames shifted (config.augment_shift; DrQ), or itself when off.

        One shift per sample for all its frames (history, o_t, o_{t+1} and the model's
        transition): the camera moves, the window stays consistent, so the history's chaining
        (history_features) and H_{t+1} = H_t + (o_t, a_t, r, o_{t+1}) still hold.
        """
        pad = self.config.augment_shift
        if pad <= 0 or self.spec.obs_kind != 'pixels':
            return batch
        names = ['obs', 'next_obs', *(['model_obs', 'model_next_obs']
                                      if batch.model_obs is not None else [])]
        k = batch.hist_obs.shape[1]
        frames = torch.cat([batch.hist_obs, batch.hist_next_obs,
                            *(getattr(batch, name).unsqueeze(1) for name in names)], dim=1)
        shifted = random_shift(frames, pad, self._shift_rng)
        fields = {name: getattr(batch, name) for name in batch.__slots__}
        fields['hist_obs'], fields['hist_next_obs'] = shifted[:, :k], shifted[:, k:2 * k]
        for i, name in enumerate(names):
            fields[name] = shifted[:, 2 * k + i]
        return HistoryBatch(**fields)

    # ------------------------------------------------------------------ update
    def update(self, batch: HistoryBatch, pair: HistoryBatch | None, step: int
               ) -> dict[str, float]:
        """One training update: representation step, critic, then actor and targets every 2.

        Args:
            batch: transitions with their histories H1.
            pair: an independently sampled batch whose histories are H2 (ZeUS context loss);
                may be None for methods that do not use it.
            step: index of this update (drives actor/target frequencies, UP-OSI warm-up).

        Returns:
            Slash-named scalar metrics, e.g. 'loss/critic', 'loss/context', 'loss/dynamics'.
        """
        if not self.optimizers:
            raise RuntimeError('this agent was built to act only (optimizers=False, e.g. loaded '
                               'with load_optimizers=False): load the checkpoint with its '
                               'optimizers to train it')
        self._check_batch(batch, 'batch')
        batch = self.augment(batch.to(self.device))
        needs_pair = self.objective.needs_pair(self.config)
        if needs_pair:
            if pair is None:
                raise ValueError(f'method {self.method} needs a pair batch for the context loss')
            self._check_batch(pair, 'pair')
            if pair.batch_size != batch.batch_size:
                raise ValueError(f'pair batch size {pair.batch_size} != batch size '
                                 f'{batch.batch_size}')
            pair = self.augment(pair.to(self.device))
        metrics: dict[str, torch.Tensor] = {}
        context, next_context = self._representation_step(
            batch, pair if needs_pair else None, step, metrics)
        norm = cast('ContextNormalizer | None', self.modules.get('context_norm'))
        if norm is not None:
            norm.update(context, next_context, batch.not_done)
            if norm.noise_scale is not None:
                metrics['train/context_reliability'] = norm.reliability().mean()
        noise = self._update_noise(batch.batch_size)
        self._update_critic(batch, context, next_context, step, metrics, noise)
        if step % self.config.actor_update_freq == 0:
            self._update_actor_and_alpha(batch, context, metrics, noise)
        if step % self.config.target_update_freq == 0:
            m = self.modules
            soft_update_params(m['critic'], m['critic_target'], self.config.critic_tau)
            soft_update_params(m['encoder'], m['encoder_target'], self.config.encoder_tau)
            if 'psi_target' in m:
                soft_update_params(m['psi'], m['psi_target'], self.config.context_target_tau)
        names = list(metrics)
        values = torch.stack([metrics[n].detach().float() for n in names]).cpu().tolist()
        return dict(zip(names, values, strict=True))

    def _representation_step(self, batch: HistoryBatch, pair: HistoryBatch | None, step: int,
                             metrics: dict[str, torch.Tensor]
                             ) -> tuple[torch.Tensor, torch.Tensor]:
        """Train phi/psi/T/R (and the decoder); return detached contexts for H_t and H_{t+1}."""
        context = next_context = None
        if self.has_representation_step and self.representation_frozen(step):
            with torch.no_grad():  # the same contexts and logged losses, nothing trained
                losses = self.objective.losses(self, batch, pair, metrics)
            metrics['loss/representation'] = losses.total
            context, next_context = losses.context, losses.next_context
        elif self.has_representation_step:
            losses = self.objective.losses(self, batch, pair, metrics)
            names = [name for name in ('encoder', 'decoder', 'psi', 'model')
                     if name in self.optimizers]
            for name in names:
                self.optimizers[name].zero_grad(set_to_none=True)
            losses.total.backward()
            for name in names:
                self.optimizers[name].step()
            metrics['loss/representation'] = losses.total
            context, next_context = losses.context, losses.next_context
        if self.uses_true_context(step):
            return batch.context.float(), batch.context.float()
        if context is None or next_context is None:
            empty = batch.obs.new_zeros(batch.batch_size, 0, dtype=torch.float32)
            return empty, empty
        return context, next_context

    def _update_critic(self, batch: HistoryBatch, context: torch.Tensor,
                       next_context: torch.Tensor, step: int,
                       metrics: dict[str, torch.Tensor],
                       noise: torch.Tensor | None = None) -> None:
        """Clipped double-Q TD step on critic + phi (SAC-AE), and on psi when configured."""
        m, cfg = self.modules, self.config
        with torch.no_grad():
            next_feat = m['encoder'](batch.next_obs)
            next_c = self.policy_context(next_context, noise)
            next_x = torch.cat([next_feat, next_c], dim=-1)
            sample = squashed_sample(m['actor'](next_x))
            target_x = torch.cat([m['encoder_target'](batch.next_obs), next_c], dim=-1)
            next_q = m['critic_target'](target_x, sample.action).min()
            soft_v = next_q - self.alpha * sample.log_prob
            target_q = batch.reward + batch.not_done * cfg.discount * soft_v
        psi_trained = (cfg.critic_context_grad and 'psi' in m
                       and not self.uses_true_context(step)
                       and not self.representation_frozen(step))
        if psi_trained:  # psi(H_t) again, with its graph, so the TD error reaches psi
            history, _ = self.history_features(batch.hist_obs, batch.hist_action,
                                               batch.hist_reward, batch.hist_next_obs,
                                               batch.hist_mask)
            context = m['psi'](history)
            self.optimizers['psi'].zero_grad(set_to_none=True)
        with torch.set_grad_enabled(not self.representation_frozen(step)):
            feat = m['encoder'](batch.obs)  # frozen: the TD loss leaves phi alone too
        x = torch.cat([feat, self.policy_context(context, noise)], dim=-1)
        q = m['critic'](x, self.normalize_action(batch.action))
        loss = F.mse_loss(q.q1, target_q) + F.mse_loss(q.q2, target_q)
        self.optimizers['critic'].zero_grad(set_to_none=True)
        loss.backward()
        self.optimizers['critic'].step()
        if psi_trained:
            self.optimizers['psi'].step()
        metrics['loss/critic'] = loss
        metrics['train/q'] = q.q1.mean()

    def _update_actor_and_alpha(self, batch: HistoryBatch, context: torch.Tensor,
                                metrics: dict[str, torch.Tensor],
                                noise: torch.Tensor | None = None) -> None:
        """Policy step on detached [phi(o), c], then the temperature step."""
        m = self.modules
        with torch.no_grad():
            x = torch.cat([m['encoder'](batch.obs), self.policy_context(context, noise)],
                          dim=-1)
        out = m['actor'](x)
        sample = squashed_sample(out)
        actor_q = m['critic'](x, sample.action).min()
        actor_loss = (self.alpha.detach() * sample.log_prob - actor_q).mean()
        if self.config.actor_bc_weight > 0 or batch.anchor is not None:
            # TD3+BC: Q on a unit scale, stay near the data (per sample when weighted)
            actor_loss = actor_loss / actor_q.abs().mean().detach().clamp_min(1e-6)
            mode = torch.tanh(out.mu)
            squared = (mode - self.normalize_action(batch.action)).square().mean(-1, True)
            bc = squared.mean()
            weighted = (self.config.actor_bc_weight * bc if batch.anchor is None
                        else (batch.anchor * squared).mean())
            actor_loss = actor_loss + weighted
            metrics['loss/actor_bc'] = bc
        self.optimizers['actor'].zero_grad(set_to_none=True)
        actor_loss.backward()
        self.optimizers['actor'].step()
        alpha_loss = (self.alpha * (-sample.log_prob - self.target_entropy).detach()).mean()
        self.optimizers['alpha'].zero_grad(set_to_none=True)
        alpha_loss.backward()
        self.optimizers['alpha'].step()
        metrics['loss/actor'] = actor_loss
        metrics['loss/alpha'] = alpha_loss
        metrics['train/alpha'] = self.alpha.detach()
        metrics['train/entropy'] = -sample.log_prob.detach().mean()

    # ------------------------------------------------------------------ inference
    def _as_tensor(self, value: Any, dtype: torch.dtype | None = None) -> torch.Tensor:
        tensor = torch.as_tensor(np.asarray(value) if not torch.is_tensor(value) else value)
        return tensor.to(self.device, dtype=dtype) if dtype else tensor.to(self.device)

    @torch.no_grad()
    def encode_context(self, hist_obs: Any, hist_action: Any, hist_reward: Any,
                       hist_next_obs: Any, hist_mask: Any) -> torch.Tensor:
        """psi(H) for batched (B, k, ...) or single (k, ...) histories; (B, C) or (C,)."""
        if self.objective.context_source == 'true':
            raise ValueError(f'method {self.method} has no context encoder: it uses the true '
                             'context')
        mask = self._as_tensor(hist_mask).bool()
        single = mask.dim() == 1
        obs_dtype = torch.uint8 if self.spec.obs_kind == 'pixels' else torch.float32
        parts = [self._as_tensor(hist_obs, obs_dtype), self._as_tensor(hist_action, torch.float32),
                 self._as_tensor(hist_reward, torch.float32).reshape(*mask.shape, 1),
                 self._as_tensor(hist_next_obs, obs_dtype)]
        if single:
            mask, parts = mask.unsqueeze(0), [p.unsqueeze(0) for p in parts]
        b, k = mask.shape
        if k != self.config.k:
            raise ValueError(f'history has {k} slots, this agent uses k={self.config.k}')
        if self.context_dim == 0 or 'psi' not in self.modules:
            out = torch.zeros(b, self.context_dim, device=self.device)
        else:
            history, _ = self.history_features(*parts, mask)
            out = self.modules['psi'](history)
        return out[0] if single else out

    @torch.no_grad()
    def act(self, obs: Any, context: Any, deterministic: bool = True) -> np.ndarray:
        """Action(s) in task bounds for one observation (obs_shape) or a batch (B, *obs_shape)."""
        obs_dtype = torch.uint8 if self.spec.obs_kind == 'pixels' else torch.float32
        obs_t = self._as_tensor(obs, obs_dtype)
        single = obs_t.dim() == len(self.spec.obs_shape)
        if single:
            obs_t = obs_t.unsqueeze(0)
        if tuple(obs_t.shape[1:]) != self.spec.obs_shape:
            raise ValueError(f'obs has shape {tuple(obs_t.shape)}, expected '
                             f'{self.spec.obs_shape} or (B, *{self.spec.obs_shape})')
        if context is None:
            context = torch.zeros(obs_t.shape[0], 0)
        ctx = self._as_tensor(context, torch.float32).reshape(obs_t.shape[0], -1)
        if ctx.shape[1] != self.context_dim:
            raise ValueError(f'context has {ctx.shape[1]} values per sample, expected '
                             f'context_dim={self.context_dim}')
        action = self.act_on_features(self.modules['encoder'](obs_t), ctx, deterministic)
        out = action.cpu().numpy()
        return out[0] if single else out

    @torch.no_grad()
    def act_on_features(self, feat: torch.Tensor, context: torch.Tensor,
                        deterministic: bool = True) -> torch.Tensor:
        """Actions in task bounds (B, A) from phi(o) (B, F) and raw contexts (B, C), unchecked.

        The one place that turns features into actions: `act`, and deployment when it already
        holds phi(o) (InferenceAgent reuse_features).
        """
        x = torch.cat([feat, self.policy_context(context, self._acting_noise(context.shape))],
                      dim=-1)
        action = squashed_sample(self.modules['actor'](x), deterministic).action
        return action * self._action_scale + self._action_bias

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict[str, Any]:
        """Network, optimizer and temperature state (tensors and plain data only)."""
        return {
            'modules': {name: module.state_dict() for name, module in self.modules.items()},
            'optimizers': {name: opt.state_dict() for name, opt in self.optimizers.items()},
            'log_alpha': self.log_alpha.detach().cpu(),
        }

    def load_state_dict(self, state: dict[str, Any], *, optimizers: bool = True,
                        only: Sequence[str] | None = None) -> None:
        """Restore what `state_dict` produced (raises KeyError/RuntimeError on mismatch).

        `only` restores just those modules (a deployment export); the others keep their init.
        """
        names = list(self.modules) if only is None else list(only)
        missing = set(names) - set(state['modules'])
        if missing:
            raise KeyError(f'state has no weights for {", ".join(sorted(missing))}')
        for name in names:
            self.modules[name].load_state_dict(state['modules'][name])
        with torch.no_grad():
            self.log_alpha.copy_(state['log_alpha'].to(self.device))
        if optimizers:
            for name, opt in self.optimizers.items():
                if name in state['optimizers']:
                    opt.load_state_dict(state['optimizers'][name])
