"""Training configuration: one dataclass, validated on construction, loadable from YAML.

Defaults follow the paper's hyper-parameter tables (appendix B) where the paper gives a value and
mtrl (the paper's starting codebase) where it does not. `alpha_psi` and `adam_beta1` may be
`'auto'`; `resolve_config(config, task)` replaces them with the task family's training defaults.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from zeus_ros.cli_args import SEED_MAX
from zeus_ros.learning.context import AGGREGATIONS, CONTEXT_HEADS
from zeus_ros.learning.errors import ConfigError
from zeus_ros.learning.methods import METHOD_REGISTRY, METHODS, method_objective

__all__ = [
    'AGGREGATIONS',
    'CONTEXT_LOSSES',
    'CONTEXT_NORMS',
    'EXPLORATIONS',
    'LEGACY_CONFIG',
    'METHODS',
    'MODEL_TARGETS',
    'ZeusConfig',
    'config_from_dict',
    'load_config',
    'resolve_config',
    'undeclared_defaults',
    'upgrade_stored_config',
]

CONTEXT_NORMS = ('none', 'running', 'reliability')
"""How the context is scaled at the actor/critic input (one normaliser for every method)."""
CONTEXT_INPUT_INITS = ('orthogonal', 'zero')
"""How the actor's and critic's first-layer weights on the context inputs start."""

CONTEXT_LOSSES = ('paper', 'scale_free', 'scale_free_bounded')
"""Form of eq. 1's context loss: as written, or distances matched up to a batch-wise scale."""

EXPLORATIONS = ('stochastic', 'noise')
"""How a trained policy collects: sampling the SAC policy (Algorithm 1) or its mode + noise."""
MODEL_TARGETS = ('latent', 'observation')
"""What T predicts: the next latent phi(o') or the normalised change of the state vector."""

LEGACY_CONFIG: dict[str, Any] = {'context_norm': 'none', 'context_loss': 'paper',
                                 'critic_context_grad': False, 'exploration': 'noise',
                                 'context_consistency': 0.0}
"""Values of the fields added with the method registry, for checkpoints written before them
(whose 'oracle' was plain SAC on the true context, now 'oracle_sac')."""




@dataclass(frozen=True)
class ZeusConfig:
    """Everything that shapes the networks and the updates of one training run."""

    method: str = 'zeus'
    """One of METHODS."""
    obs_kind: str = 'state'
    """'state' (float vectors, MLP phi) or 'pixels' (3 stacked 84x84 RGB frames, conv phi)."""
    k: int = 5
    """History length: transitions psi sees (paper: context length 5)."""
    aggregation: str = 'mean'
    """How psi combines the k transition encodings: one of AGGREGATIONS."""
    context_dim: int = 10
    """Size of psi(H) (ignored for no_context: 0, up_osi/oracle: number of context params)."""
    transition_dim: int = 64
    """Size of psi's per-transition encoding before aggregation."""
    context_hidden_dim: int = 128
    """Width of the two hidden layers of psi's per-transition MLP."""
    alpha_psi: float | str = 'auto'
    """Weight of the context loss (eq. 1); 'auto' = the task family's `training: alpha_psi`."""
    context_loss: str = 'scale_free'
    """'paper': MSE(||psi1 - psi2||, d) as eq. 1 writes it, which psi can satisfy by shrinking
    towards a constant (d is computed at psi itself); 'scale_free': both distance vectors divided
    by their batch mean before the MSE, so only the pattern of distances counts, not their size;
    'scale_free_bounded': the same target, its gradient at the scale of psi's distances (the loss
    times the detached mean psi distance squared). Why (session 10): dividing by the mean
    multiplies the gradient by 1 / (mean psi distance), so a tight psi is driven by this loss
    alone and the dynamics loss's signal is drowned; on Cheetah-Bias-v0 psi's codes then
    saturate, while without the context loss psi reads the bias (Spearman 0.97)."""
    context_consistency: float = 0.0
    """Weight of the consistency loss (representation.consistency_loss): psi should drift little
    from one step to the next of an episode relative to its spread across the batch. 0: off."""
    context_head: str = 'linear'
    """After the aggregation: 'linear' (psi a linear map of the aggregated codes, the paper's
    reading) or 'mlp' (Deep Sets' rho: a ReLU MLP of context_hidden_dim, so psi can combine what
    the transitions say instead of averaging it; measured in docs/results_notebook.md,
    session 5)."""
    context_code_norm: bool = False
    """True: psi's per-transition pre-activations are layer-normalised (no learned scale)
    before the tanh, so the codes cannot saturate. Why (session 9): on Cheetah-Motor-v0 every
    code of the collapsed psi runs was at +-1 (the tanh's gradient ~0, so psi could not
    recover: a flat psi), against 0.1% in the run whose psi read the motor gain."""
    model_horizon: int = 1
    """Which transition the context-conditioned models (T and R of zeus, cadm's pair) predict
    from psi(H_t): one drawn uniformly from the `model_horizon` transitions that start at o_t,
    clamped to the episode (1: the next one, as the paper). The next reward is predicted well by
    the rewards just seen, whatever the context; a transition further on, from another state, is
    predicted only by what stays constant, so psi has to encode the context rather than its
    history's reward level (docs/results_notebook.md, session 6). Uses no context labels."""
    context_norm: str = 'none'
    """'running': standardise the context (psi or the true one) at the actor/critic input with
    running statistics of the training batches; 'none': feed it raw (the paper, and the default:
    where psi carries no signal the normaliser turns its noise into unit-size inputs, which broke
    learning on Cheetah-Run-v0, docs/results.md); 'reliability': standardised as 'running', then
    each dimension weighted by the share of its variance that is not within-episode noise
    (context.ContextNormalizer), so a psi without signal fades to 0 instead of being amplified."""
    context_norm_momentum: float = 0.01
    """Update rate of the running context statistics."""
    context_input_init: str = 'orthogonal'
    """'orthogonal': the actor's and critic's first-layer weights on the context inputs start
    like the others; 'zero': they start at 0, so the networks begin as no_context and weight the
    context only as far as its correlation with their losses builds those weights up (noise in
    psi averages out of the gradient instead of entering at full strength from update 0)."""
    critic_context_grad: bool = False
    """True: the critic's TD loss trains psi too. Measured harmful at every budget we ran
    (docs/results.md); False: psi is trained by its method's objective only and reaches actor and
    critic detached."""
    context_target_tau: float = 0.0
    """> 0: a slow (EMA) copy of psi encodes H_{t+1} for the TD target, updated with this rate
    at `target_update_freq` like the critic's and encoder's targets (SAC-AE), so that with
    `critic_context_grad` the target does not move with every psi step. 0: online psi."""
    context_noise: float = 0.0
    """> 0 (a diagnostic): Gaussian noise of this standard deviation is added to the context at
    the actor/critic input, after the normaliser (so in units of the context's spread), at every
    use: updates, collection, evaluation and deployment. On the oracle it answers how exact an
    inferred context must be for knowing it to pay (docs/results_notebook.md, session 5).
    0: off."""
    context_noise_steps: int = 0
    """How long one `context_noise` error persists. 0: drawn fresh at every use (c_t and c_{t+1}
    of one TD target get independent errors). > 0: an error that persists like an estimate's:
    one draw per sample shared by every use in an update (critic, TD target, actor), and in
    acting an AR(1) process with this time constant in steps (psi's error over a k-step
    window changes slowly too)."""
    representation_frozen_from: int = 0
    """> 0: from this update on phi, psi and the models stop training (their losses are still
    logged) and actor and critic keep training on the fixed representation, so the context
    they condition on stops moving under them (a `context_norm` keeps updating its running
    statistics, which settle). A test of whether psi's drift (half its spread
    per 10k updates, docs/results.md session 4) is what stops ZeUS improving; it may be set on
    a resume that has not reached it. 0: never (the paper)."""
    exploration: str = 'stochastic'
    """How `zeus loop` collects with a trained policy: 'stochastic' samples the SAC policy (the
    paper's Algorithm 1); 'noise' acts deterministically plus Gaussian noise (--noise)."""
    cadm_beta: float = 0.5
    """CaDM backward-dynamics loss weight (paper's CaDM table: 0.5)."""
    up_osi_warmup_fraction: float = 0.01
    """UP-OSI: fraction of num_updates during which the policy sees the true context."""
    dynamics_loss: str = 'gaussian_nll'
    """'gaussian_nll' (trains mu and sigma, so the W2 term of d is meaningful) or 'mse' on mu."""
    model_target: str = 'latent'
    """What the transition models (T, CaDM's backward model) predict: 'latent' phi(o') (the
    paper, mtrl's DeepMDP) or 'observation', the change of the normalised state
    (o' - o) / obs_std (state observations only, as CaDM). Why (session 9): on
    Cheetah-Motor-v0 the motor gain explains 0.4-0.6 of the one-step state change a linear
    model leaves, but psi stays flat under the latent target."""
    feature_dim: int = 50
    """Size of phi(o) (SAC-AE: 50)."""
    num_conv_layers: int = 4
    """Pixel phi: number of 3x3 conv layers (first has stride 2)."""
    num_filters: int = 32
    """Pixel phi: filters per conv layer."""
    augment_shift: int = 0
    """Pixels: DrQ's random shift (learning/augment.py) of up to this many pixels, one shift
    per sample for its whole window (history, o_t, o_{t+1}), drawn anew at every update. Why:
    it is what lets a small pixel encoder learn from few frames (DrQ, Kostrikov et al. 2020);
    0 (the default): no augmentation, every earlier run unchanged."""
    encoder_hidden_dim: int = 256
    """State phi: width of the hidden layer of the MLP encoder."""
    hidden_dim: int = 1024
    """Actor / critic hidden width (2 hidden layers)."""
    model_hidden_dim: int = 512
    """T and R hidden width (1 hidden layer, paper table)."""
    batch_size: int = 128
    """Transitions per update (and per pair batch)."""
    num_updates: int = 1_000_000
    """Gradient updates of a training run."""
    seed_steps: int = 1500
    """Uniform-random environment steps before learning when collecting online (paper: 1500)."""
    eval_interval: int = 10_000
    """Updates between evaluations."""
    eval_episodes: int = 10
    """Episodes per evaluation."""
    checkpoint_interval: int = 50_000
    """Updates between checkpoints."""
    log_interval: int = 1000
    """Updates between metric rows."""
    discount: float = 0.99
    """Discount gamma."""
    critic_tau: float = 0.01
    """Soft-update rate of the target Q heads."""
    encoder_tau: float = 0.05
    """Soft-update rate of the target encoder phi."""
    actor_update_freq: int = 2
    """Actor (and temperature) update every this many updates."""
    target_update_freq: int = 2
    """Target network update every this many updates."""
    actor_lr: float = 3e-4
    """Adam learning rate of the policy."""
    actor_bc_weight: float = 0.0
    """Behaviour-cloning weight of the actor loss (TD3+BC, Fujimoto & Gu 2021): > 0 divides
    the SAC actor loss by mean |Q| and adds this x the squared distance of the policy's mode
    to the batch's actions. 0 (training from scratch): plain SAC. Continual rounds fine-tune a
    working policy on a few thousand steps; without it the actor climbs the fresh critic's
    errors (measured: train-value returns -39 -> -308 after 1,000 updates)."""
    actor_gate: int = 0
    """Centroids of a novelty-gated actor (learning/gated_actor.py): > 0, the actor is the
    deployed one wherever the policy's context is near one of these training contexts and an
    adapted copy where it is new (continual rounds set it). 0: one actor."""
    critic_lr: float = 3e-4
    """Adam learning rate of the Q functions (and of phi through the critic loss)."""
    encoder_lr: float = 1e-3
    """Adam learning rate of phi for the model and autoencoder losses."""
    decoder_lr: float = 1e-3
    """Adam learning rate of the pixel decoder."""
    context_lr: float = 1e-3
    """Adam learning rate of psi."""
    model_lr: float = 1e-3
    """Adam learning rate of T and R (and CaDM's backward model)."""
    alpha_lr: float = 1e-4
    """Adam learning rate of the temperature."""
    adam_beta1: float | str = 'auto'
    """Adam beta1 of policy, Q and temperature; 'auto' = the task family's `training:` value."""
    init_temperature: float = 0.1
    """Initial SAC temperature."""
    actor_log_std_min: float = -10.0
    """Lower bound of the actor's log std."""
    actor_log_std_max: float = 2.0
    """Upper bound of the actor's log std."""
    decoder_latent_lambda: float = 1e-6
    """L2 weight on phi(o) in the SAC-AE autoencoder loss (pixels only)."""
    decoder_weight_decay: float = 1e-7
    """Weight decay of the decoder optimizer (SAC-AE)."""
    device: str = 'auto'
    """'auto' (CUDA if available), 'cpu', 'cuda' or 'cuda:N'."""
    seed: int = 0
    """Seed for torch, NumPy and Python."""

    def __post_init__(self) -> None:
        """Reject bad values early, naming the field."""
        _check_choice('method', self.method, tuple(METHOD_REGISTRY))
        _check_choice('obs_kind', self.obs_kind, ('state', 'pixels'))
        _check_choice('aggregation', self.aggregation, AGGREGATIONS)
        _check_choice('dynamics_loss', self.dynamics_loss, ('gaussian_nll', 'mse'))
        _check_choice('model_target', self.model_target, MODEL_TARGETS)
        if self.model_target == 'observation' and self.obs_kind != 'state':
            raise ConfigError("model_target 'observation' predicts the change of the state "
                              f"vector; obs_kind is {self.obs_kind!r}: use model_target "
                              "'latent' for pixels")
        _check_choice('context_loss', self.context_loss, CONTEXT_LOSSES)
        _check_choice('context_head', self.context_head, CONTEXT_HEADS)
        _check_choice('context_norm', self.context_norm, CONTEXT_NORMS)
        _check_choice('context_input_init', self.context_input_init, CONTEXT_INPUT_INITS)
        if self.context_norm == 'reliability' and self.aggregation not in ('mean', 'sum'):
            raise ConfigError(f"context_norm 'reliability' estimates psi's noise from one step "
                              f'of a mean or sum over k transitions; aggregation is '
                              f"{self.aggregation!r}: use aggregation mean or sum, or "
                              f"context_norm 'running'")
        _check_float('context_noise', self.context_noise, low=0.0)
        if isinstance(self.context_noise_steps, bool) or not isinstance(
                self.context_noise_steps, int) or self.context_noise_steps < 0:
            raise ConfigError(f'context_noise_steps must be an integer >= 0, '
                              f'got {self.context_noise_steps!r}')
        if self.context_noise > 0 and self.context_norm == 'none':
            raise ConfigError(f'context_noise={self.context_noise} is in units of the '
                              "normalised context, but context_norm is 'none': set context_norm "
                              "'running' (or 'reliability')")
        if isinstance(self.representation_frozen_from, bool) or not isinstance(
                self.representation_frozen_from, int) or self.representation_frozen_from < 0:
            raise ConfigError(f'representation_frozen_from must be an integer >= 0 (0: never), '
                              f'got {self.representation_frozen_from!r}')
        _check_choice('exploration', self.exploration, EXPLORATIONS)
        for flag in ('critic_context_grad', 'context_code_norm'):
            if not isinstance(getattr(self, flag), bool):
                raise ConfigError(f'{flag} must be true or false, got {getattr(self, flag)!r}')
        for name in ('k', 'model_horizon', 'context_dim', 'transition_dim', 'context_hidden_dim',
                     'feature_dim',
                     'num_conv_layers', 'num_filters', 'encoder_hidden_dim', 'hidden_dim',
                     'model_hidden_dim', 'batch_size', 'num_updates', 'eval_interval',
                     'eval_episodes', 'checkpoint_interval', 'log_interval',
                     'actor_update_freq', 'target_update_freq'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f'{name} must be a positive integer, got {value!r}')
        if isinstance(self.augment_shift, bool) or not isinstance(self.augment_shift, int) \
                or self.augment_shift < 0:
            raise ConfigError(f'augment_shift must be an integer >= 0 (pixels; 0: off), '
                              f'got {self.augment_shift!r}')
        if self.augment_shift > 0 and self.obs_kind != 'pixels':
            raise ConfigError(f'augment_shift={self.augment_shift} shifts frames; obs_kind is '
                              f'{self.obs_kind!r}: use 0 for state observations')
        if isinstance(self.seed_steps, bool) or not isinstance(self.seed_steps, int) \
                or self.seed_steps < 0:
            raise ConfigError(f'seed_steps must be an integer >= 0, got {self.seed_steps!r}')
        if isinstance(self.actor_gate, bool) or not isinstance(self.actor_gate, int) \
                or self.actor_gate < 0:
            raise ConfigError(f'actor_gate must be an integer >= 0 (0: one actor), got '
                              f'{self.actor_gate!r}')
        for name in ('actor_lr', 'critic_lr', 'encoder_lr', 'decoder_lr', 'context_lr',
                     'model_lr', 'alpha_lr', 'init_temperature'):
            _check_float(name, getattr(self, name), low=0.0, low_open=True)
        for name in ('critic_tau', 'encoder_tau', 'discount', 'up_osi_warmup_fraction',
                     'context_norm_momentum', 'context_target_tau'):
            _check_float(name, getattr(self, name), low=0.0, high=1.0)
        for name in ('cadm_beta', 'decoder_latent_lambda', 'decoder_weight_decay',
                     'context_consistency', 'actor_bc_weight'):
            _check_float(name, getattr(self, name), low=0.0)
        _check_float('actor_log_std_min', self.actor_log_std_min)
        _check_float('actor_log_std_max', self.actor_log_std_max)
        if self.actor_log_std_min >= self.actor_log_std_max:
            raise ConfigError('actor_log_std_min must be below actor_log_std_max, got '
                              f'{self.actor_log_std_min} >= {self.actor_log_std_max}')
        if self.alpha_psi != 'auto':
            _check_float('alpha_psi', self.alpha_psi, low=0.0)
        if self.adam_beta1 != 'auto':
            _check_float('adam_beta1', self.adam_beta1, low=0.0, high=1.0, high_open=True)
        if not isinstance(self.device, str) or not (
                self.device in ('auto', 'cpu', 'cuda') or self.device.startswith('cuda:')):
            raise ConfigError(f"device must be 'auto', 'cpu', 'cuda' or 'cuda:N', "
                              f'got {self.device!r}')
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) \
                or not 0 <= self.seed <= SEED_MAX:
            raise ConfigError(f"seed must be an integer in [0, {SEED_MAX}] (numpy's seed "
                              f'range), got {self.seed!r}')

        _check_memory(self)

    def to_dict(self) -> dict[str, Any]:
        """Plain-data copy (for YAML, checkpoints and logs)."""
        return dataclasses.asdict(self)

    def replace(self, **changes: Any) -> ZeusConfig:
        """Copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


def memory_estimate(config: ZeusConfig) -> dict[str, int]:
    """Bytes the networks and one batch need at least, by the config key that sizes them.

    A lower bound, from the widths alone (observation and action sizes count as 1): each
    trained parameter takes 4 bytes 4 times (the weight, Adam's two moments, its gradient),
    each target copy 4 bytes; a batch's activations 4 bytes each, twice (their gradients).
    """
    trained, word = 4 * 4, 4
    h, f, c = config.hidden_dim, config.feature_dim, config.context_dim
    policy_in = f + c
    actor = policy_in * h + h * h
    critic = 2 * (policy_in * h + h * h)  # two Q heads, and a target copy of both
    sizes = {'hidden_dim': (actor + critic) * trained + critic * word}
    m = config.model_hidden_dim
    sizes['model_hidden_dim'] = ((policy_in + 1) * m * 2 + 2 * m * f + m) * trained
    ch, t = config.context_hidden_dim, config.transition_dim
    sizes['context_hidden_dim'] = (2 * ch * ch + ch * (t + c + f)) * trained
    if config.obs_kind == 'pixels':
        side = max(1, 41 - 2 * (config.num_conv_layers - 1))  # 84x84 frames, see encoders.py
        nf = config.num_filters
        encoder = 9 * nf * nf * config.num_conv_layers + nf * side * side * f
        sizes['num_filters'] = encoder * (2 * trained + word)  # phi, its decoder, target phi
        frame = 9 * 84 * 84
    else:
        sizes['encoder_hidden_dim'] = config.encoder_hidden_dim * (f + 1) * (trained + word)
        frame = 1
    activations = (config.k + 2) * (frame + config.encoder_hidden_dim + 2 * ch) + 6 * h + 2 * m
    sizes['batch_size'] = config.batch_size * activations * word * 2
    return sizes


def memory_limit() -> int:
    """Bytes of physical memory of this machine (0 where it cannot be asked)."""
    import os

    try:
        return int(os.sysconf('SC_PAGE_SIZE')) * int(os.sysconf('SC_PHYS_PAGES'))
    except (AttributeError, OSError, ValueError):
        return 0


def _check_memory(config: ZeusConfig) -> None:
    """Refuse sizes whose networks could not fit in this machine's memory: one line."""
    limit = memory_limit()
    sizes = memory_estimate(config)
    total = sum(sizes.values())
    if limit <= 0 or total <= limit:
        return
    key = max(sizes, key=lambda name: sizes[name])
    default = getattr(ZeusConfig, key)
    raise ConfigError(f'{key}={getattr(config, key)}: the networks and a batch would need at '
                      f'least {_bytes_text(total)} (parameters x 4 bytes x weights, Adam moments '
                      f'and gradients), more than the {_bytes_text(limit)} of memory of this '
                      f'machine; use a smaller {key} (default {default})')


def _bytes_text(size: float) -> str:
    for unit in ('bytes', 'KiB', 'MiB', 'GiB', 'TiB'):
        if size < 1024 or unit == 'TiB':
            return f'{size:.0f} {unit}' if unit == 'bytes' else f'{size:.1f} {unit}'
        size /= 1024
    return f'{size:.1f} TiB'  # pragma: no cover - the loop returns


def _check_choice(name: str, value: object, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ConfigError(f'{name} must be one of {", ".join(choices)}; got {value!r}')


def _check_float(name: str, value: object, *, low: float | None = None,
                 high: float | None = None, low_open: bool = False,
                 high_open: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f'{name} must be a number, got {value!r}')
    if low is not None and (value < low or (low_open and value == low)):
        raise ConfigError(f'{name} must be {">" if low_open else ">="} {low}, got {value!r}')
    if high is not None and (value > high or (high_open and value == high)):
        raise ConfigError(f'{name} must be {"<" if high_open else "<="} {high}, got {value!r}')


def config_from_dict(data: dict[str, Any], *, source: str = 'config') -> ZeusConfig:
    """Build a config from plain data, rejecting unknown keys (typos must not pass silently)."""
    if not isinstance(data, dict):
        raise ConfigError(f'{source}: expected a mapping of config keys, '
                          f'got {type(data).__name__}')
    known = {field.name for field in fields(ZeusConfig)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f'{source}: unknown config key(s) {", ".join(map(str, unknown))}; '
                          f'known keys: {", ".join(sorted(known))}')
    values = dict(data)
    for name in ('actor_lr', 'critic_lr', 'encoder_lr', 'decoder_lr', 'context_lr', 'model_lr',
                 'alpha_lr', 'decoder_weight_decay', 'decoder_latent_lambda'):
        # YAML 1.1 reads '3e-4' (no dot) as a string; accept it as the number it means.
        if isinstance(values.get(name), str):
            try:
                values[name] = float(values[name])
            except ValueError:
                raise ConfigError(f'{source}: {name} must be a number, '
                                  f'got {values[name]!r}') from None
    try:
        return ZeusConfig(**values)
    except ConfigError as error:
        raise ConfigError(f'{source}: {error}') from None


def upgrade_stored_config(data: dict[str, Any]) -> dict[str, Any]:
    """A stored config from before the method registry, with the values it was trained with."""
    if not isinstance(data, dict) or 'context_norm' in data:
        return data
    upgraded = {**LEGACY_CONFIG, **data}
    if upgraded.get('method') == 'oracle':
        upgraded['method'] = 'oracle_sac'
    return upgraded


def load_config(path: str | Path) -> ZeusConfig:
    """Read a YAML training config; unknown keys and bad values raise ConfigError.

    `base: other.yaml` (a path relative to the file) starts from that config and overrides
    the keys given, so a variant holds only what it changes.
    """
    return config_from_dict(_read_config_data(Path(path), ()), source=str(path))


def _read_config_data(path: Path, children: tuple[Path, ...]) -> Any:
    """The YAML mapping of a config file with its `base:` chain resolved."""
    try:
        text = path.read_text()
    except OSError as error:
        via = f' (base of {children[-1]})' if children else ''
        raise ConfigError(f'{path}{via}: cannot read config ({error.strerror})') from None
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as error:
        raise ConfigError(f'{path}: not valid YAML ({error})') from None
    if not isinstance(data, dict) or 'base' not in data:
        return data
    base = data.pop('base')
    if not isinstance(base, str) or not base:
        raise ConfigError(f'{path}: base must be the path of another config file '
                          f'(relative to this one), got {base!r}')
    base_path = path.parent / base
    chain = (*children, path)
    if base_path.resolve() in {p.resolve() for p in chain}:
        raise ConfigError(f'{path}: base {base} leads back to itself '
                          f'({" -> ".join(str(p) for p in (*chain, base_path))})')
    return {**_read_config_data(base_path, chain), **data}


def undeclared_defaults(config: ZeusConfig, task: str) -> str | None:
    """One line when `alpha_psi: auto` takes a value the task's family does not declare.

    A family file without `training: alpha_psi` (a user's own task file) gets
    DEFAULT_TRAINING's 1.0, a guess: the built-in families declare 0.0 to 2.0, and on the
    Cheetah dynamics families 1.0 saturates psi so the actor ignores it. Not refused (a task
    file that trains is kept working), but said, with the value and where to declare one.
    """
    if config.alpha_psi != 'auto':
        return None
    from sim_bridge.families import family

    try:
        declared = family(task)
    except ValueError:
        return None  # resolve_config refuses this one with its own message
    objective = method_objective(config.method)
    if ('alpha_psi' in declared.declared_training or not objective.reads('alpha_psi')
            or 'alpha_psi' in objective.fixed):
        return None  # declared, or a method that never weighs the context loss
    return (f"alpha_psi auto -> {declared.training['alpha_psi']} for {task}: "
            f'{declared.source} declares no `training: {{alpha_psi: ...}}`, so this is the '
            "paper's most common value, not a measured one (the built-in families use 0.0-2.0; "
            'on Cheetah-Bias/Motor 1.0 saturates psi and the actor ignores it): declare it in '
            'the task file or pass --set alpha_psi=VALUE')


def resolve_config(config: ZeusConfig, task: str) -> ZeusConfig:
    """Replace 'auto' values with the task family's training defaults; apply method overrides.

    The family declares them (params/tasks/<task>.yaml or a task file's `training:`): the
    paper's hyper-parameter table on its tasks, our measured values on ours.
    """
    alpha_psi, beta1 = config.alpha_psi, config.adam_beta1
    if alpha_psi == 'auto' or beta1 == 'auto':
        from sim_bridge.families import DEFAULT_TRAINING, family

        try:
            defaults = family(task).training
        except ValueError as error:
            if alpha_psi == 'auto':  # no safe guess: it changes what psi learns
                raise ConfigError(f"alpha_psi 'auto' needs the task family's training "
                                  f'defaults: {error}; or set alpha_psi to a number') from None
            defaults = DEFAULT_TRAINING  # beta1 of every dynamics family in the paper
        alpha_psi = defaults['alpha_psi'] if alpha_psi == 'auto' else alpha_psi
        beta1 = defaults['adam_beta1'] if beta1 == 'auto' else beta1
    pinned = method_objective(config.method).fixed  # e.g. the ablation's alpha_psi = 0
    return config.replace(**{'alpha_psi': float(alpha_psi), 'adam_beta1': float(beta1),
                             **pinned})
