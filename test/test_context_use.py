"""Issue 10: the method registry, the options that stop the context collapse, the diagnostics."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from zeus_ros.learning import ZeusConfig, make_agent
from zeus_ros.learning.config import LEGACY_CONFIG, config_from_dict, upgrade_stored_config
from zeus_ros.learning.context import ContextNormalizer
from zeus_ros.learning.errors import ConfigError
from zeus_ros.learning.inference import InferenceAgent
from zeus_ros.learning.methods import METHOD_REGISTRY, method_objective
from zeus_ros.learning.models import RewardModel, TransitionModel
from zeus_ros.learning.representation import context_loss
from zeus_ros.learning.synthetic import SyntheticSystem
from zeus_ros.offline.evaluation.diagnostics import (
    context_sensitivity,
    extreme_indices,
    farthest_extreme,
    spread_over_noise,
)
from zeus_ros.offline.evaluation.evaluate import parse_values, switching_order
from zeus_ros.offline.evaluation.report import headroom_rows
from zeus_ros.offline.rollout import Trace

torch.set_num_threads(1)


def _config(method: str, **changes: object) -> ZeusConfig:
    base = dict(method=method, k=3, alpha_psi=1.0, hidden_dim=32, model_hidden_dim=32,
                context_hidden_dim=32, encoder_hidden_dim=32, transition_dim=8, context_dim=4,
                batch_size=8, device='cpu')
    base.update(changes)
    return ZeusConfig(**base)


@pytest.mark.parametrize('name', list(METHOD_REGISTRY))
def test_registry_entry_decides_what_the_agent_builds(name: str) -> None:
    """The context encoder exists iff the context is learned; declared models; one normaliser."""
    spec = method_objective(name)
    agent = make_agent(_config(name, context_norm='running'), SyntheticSystem(k=3).spec())
    assert ('psi' in agent.modules) == (spec.context_source == 'psi')
    for model in ('transition', 'reward', 'backward'):
        assert (model in agent.modules) == (model in spec.models), model
    assert ('context_norm' in agent.modules) == (spec.context_source != 'none')
    plain = make_agent(_config(name, context_norm='none'), SyntheticSystem(k=3).spec())
    assert 'context_norm' not in plain.modules


def test_unknown_method_lists_the_registry() -> None:
    """A typo names every method."""
    with pytest.raises(ValueError, match='oracle_sac'):
        method_objective('oracel')
    with pytest.raises(ConfigError, match='oracle_sac'):
        _config('oracel')


def test_oracle_trains_zeus_models_on_the_true_context() -> None:
    """The oracle has ZeUS's models and losses, and no context encoder to call."""
    system = SyntheticSystem(k=3)
    agent = make_agent(_config('oracle'), system.spec())
    metrics = agent.update(system.sample(8), None, 0)
    assert {'loss/dynamics', 'loss/reward', 'loss/critic'} <= set(metrics)
    assert InferenceAgent(agent).needs_true_context
    with pytest.raises(ValueError, match='true context'):
        agent.encode_context(*[np.zeros((3, *s)) for s in ((5,), (2,), (1,), (5,))],
                             np.ones(3, bool))
    sac = make_agent(_config('oracle_sac'), system.spec())
    assert 'loss/dynamics' not in sac.update(system.sample(8), None, 0)


def test_context_normalizer_standardises_in_training_only() -> None:
    """Statistics follow training batches; applying the normaliser never moves them."""
    norm = ContextNormalizer(3, momentum=1.0)
    batch = torch.randn(256, 3) * torch.tensor([1e-3, 1.0, 50.0]) + 7.0
    norm.update(batch)
    out = norm(batch)
    torch.testing.assert_close(out.mean(0), torch.zeros(3), atol=1e-3, rtol=0)
    torch.testing.assert_close(out.std(0, unbiased=False), torch.ones(3), atol=1e-2, rtol=0)
    before = norm.state_dict()['mean'].clone()
    norm(torch.randn(8, 3))
    torch.testing.assert_close(norm.state_dict()['mean'], before)


def _history_contexts(k: int, noise: float, episodes: int = 256, steps: int = 40,
                      seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """psi(H_t), psi(H_{t+1}) pairs of a mean-over-k encoder with per-episode signal.

    Dimension 0 is noise only; dimension 1 adds a per-episode signal of unit variance.
    """
    gen = torch.Generator().manual_seed(seed)
    codes = torch.randn(episodes, steps + k, 2, generator=gen) * noise
    signal = torch.randn(episodes, 1, generator=gen)
    psi = codes.unfold(1, k, 1).mean(-1)  # (episodes, steps + 1, 2): mean of the last k codes
    psi[..., 1] += signal
    return psi[:, :-1].reshape(-1, 2), psi[:, 1:].reshape(-1, 2)


def test_reliability_normaliser_fades_noise_and_keeps_signal() -> None:
    """Without labels: a noise-only dimension is weighted ~0, a signal dimension by its share."""
    k, noise = 10, 1.0
    context, next_context = _history_contexts(k, noise)
    norm = ContextNormalizer(2, momentum=1.0, noise_scale=k / 2)
    norm.update(context, next_context)
    reliability = norm.reliability()
    expected = 1.0 / (1.0 + noise ** 2 / k)  # signal variance / (signal + noise variance)
    assert float(reliability[0]) < 0.1
    assert abs(float(reliability[1]) - expected) < 0.05
    out = norm(context)
    assert float(out[:, 0].std()) < 0.1  # the noise no longer enters at unit size
    assert abs(float(out[:, 1].std()) - expected) < 0.06
    plain = ContextNormalizer(2, momentum=1.0)  # 'running' amplifies the noise to unit size
    plain.update(context)
    assert abs(float(plain(context)[:, 0].std()) - 1.0) < 0.01
    # rows whose next step is another episode are left out of the noise estimate
    jumbled = next_context[torch.randperm(len(next_context), generator=torch.Generator()
                                          .manual_seed(1))]
    masked = ContextNormalizer(2, momentum=1.0, noise_scale=k / 2)
    masked.update(context, jumbled, torch.zeros(len(context), 1))
    torch.testing.assert_close(masked.noise_var, (k / 2) * (jumbled - context).pow(2).mean(0))
    kept = ContextNormalizer(2, momentum=1.0, noise_scale=k / 2)
    same = torch.ones(len(context), 1)
    same[::2] = 0
    kept.update(context, next_context, same)
    assert abs(float(kept.reliability()[1]) - expected) < 0.06


def test_reliability_normaliser_in_the_agent(tmp_path) -> None:
    """Psi methods estimate noise, the oracle's true context is fully reliable; both round-trip."""
    from zeus_ros.learning.checkpoint import load_checkpoint, save_checkpoint

    system = SyntheticSystem(k=3)
    zeus = make_agent(_config('zeus', context_norm='reliability'), system.spec())
    assert zeus.modules['context_norm'].noise_scale == 3 / 2
    metrics = {}
    for step in range(3):
        metrics = zeus.update(system.sample(8), system.sample(8), step)
    assert 0.0 <= metrics['train/context_reliability'] <= 1.0
    oracle = make_agent(_config('oracle', context_norm='reliability'), system.spec())
    oracle.update(system.sample(8), None, 0)
    assert bool((oracle.modules['context_norm'].reliability() == 1).all())
    path = save_checkpoint(tmp_path / 'zeus.pt', zeus, step=3)
    loaded = load_checkpoint(path).agent.modules['context_norm']
    torch.testing.assert_close(loaded.noise_var, zeus.modules['context_norm'].noise_var)
    with pytest.raises(ConfigError, match='aggregation'):
        _config('zeus', context_norm='reliability', aggregation='max')


def test_context_noise_perturbs_the_normalised_context_at_every_use() -> None:
    """Diagnostic noise: the configured std after the normaliser, fresh per call, off by default.

    It needs a normaliser to have a unit.
    """
    system = SyntheticSystem(k=3)
    oracle = make_agent(_config('oracle', context_norm='running', context_noise=0.5),
                        system.spec())
    oracle.update(system.sample(8), None, 0)
    oracle.modules['context_norm'].eval()
    context = system.sample(8).context.float()[:1].expand(20000, -1)
    clean = oracle.modules['context_norm'](context)
    first, second = oracle.policy_context(context), oracle.policy_context(context)
    assert float((first - clean).std()) == pytest.approx(0.5, rel=0.05)
    assert abs(float((first - clean).mean())) < 0.02
    assert not torch.equal(first, second)
    plain = make_agent(_config('oracle', context_norm='running'), system.spec())
    plain.modules['context_norm'].eval()
    torch.testing.assert_close(plain.policy_context(context), plain.policy_context(context))
    with pytest.raises(ConfigError, match="context_norm is 'none'"):
        _config('oracle', context_norm='none', context_noise=0.5)
    with pytest.raises(ConfigError, match='context_noise'):
        _config('oracle', context_norm='running', context_noise=-1.0)


def test_persistent_context_noise_is_shared_in_updates_and_slow_in_acting() -> None:
    """context_noise_steps > 0: one error per sample for all uses, an AR(1) error in acting."""
    system = SyntheticSystem(k=3)
    oracle = make_agent(_config('oracle', context_norm='running', context_noise=0.5,
                                context_noise_steps=10), system.spec())
    shared = oracle._update_noise(4000)
    assert shared.shape == (4000, oracle.context_dim)
    assert float(shared.std()) == pytest.approx(0.5, rel=0.05)
    errors = torch.stack([oracle._acting_noise(torch.Size((2000, oracle.context_dim)))
                          for _ in range(30)])
    assert float(errors.std()) == pytest.approx(0.5, rel=0.1)
    step_change = float((errors[1:] - errors[:-1]).std())
    assert step_change == pytest.approx(0.5 * math.sqrt(2 * (1 - math.exp(-0.1))), rel=0.1)
    obs = np.zeros(system.spec().obs_shape, np.float32)
    context = np.zeros(system.spec().num_context_params, np.float32)
    assert not np.array_equal(oracle.act(obs, context), oracle.act(obs, context))
    fresh = make_agent(_config('oracle', context_norm='running', context_noise=0.5),
                       system.spec())
    assert fresh._update_noise(8) is None and fresh._acting_noise(torch.Size((1, 2))) is None
    for metrics in (oracle.update(system.sample(8), None, step) for step in range(2)):
        assert np.isfinite(metrics['loss/critic'])
    with pytest.raises(ConfigError, match='context_noise_steps'):
        _config('oracle', context_norm='running', context_noise=0.5, context_noise_steps=-1)


def test_scale_free_context_loss_ignores_the_size_of_psi() -> None:
    """Shrinking psi 1000x lowers eq. 1 as written but leaves the scale-free form unchanged."""
    torch.manual_seed(0)
    transition, reward = TransitionModel(6, 2, 4, 16), RewardModel(6, 2, 4, 16)
    feat, action = torch.randn(32, 6), torch.rand(32, 2) * 2 - 1
    psi1, psi2 = torch.randn(32, 4), torch.randn(32, 4)

    def loss(scale: float, scale_free: bool) -> float:
        return float(context_loss(transition, reward, feat, action, psi1 * scale, psi2 * scale,
                                  scale_free=scale_free).loss)

    # d is computed at psi, so shrinking psi also changes d: compare patterns, not values
    assert loss(1e-3, False) < loss(1.0, False)
    shrunk = context_loss(transition, reward, feat, action, psi1 * 1e-3, psi2 * 1e-3,
                          scale_free=True)
    ratio = shrunk.context_distance / shrunk.context_distance.mean()
    assert float(ratio.std()) > 0.1  # the pattern survives the shrinking
    assert np.isfinite(loss(1e-3, True))


def test_bounded_scale_free_loss_has_the_same_target_and_a_gradient_at_psi_scale() -> None:
    """scale_free's gradient into psi grows as psi shrinks (x1/s); the bounded form's shrinks."""
    torch.manual_seed(0)
    transition, reward = TransitionModel(6, 2, 4, 16), RewardModel(6, 2, 4, 16)
    feat, action = torch.randn(32, 6), torch.rand(32, 2) * 2 - 1
    base1, base2 = torch.randn(32, 4), torch.randn(32, 4)

    def grad_norm(scale: float, bounded: bool) -> tuple[float, float, float]:
        psi1 = (base1 * scale).requires_grad_()
        out = context_loss(transition, reward, feat, action, psi1, base2 * scale,
                           scale_free=True, bounded=bounded)
        out.loss.backward()
        return float(psi1.grad.norm()), float(out.loss), float(out.context_distance.mean())

    free_big, free_small = grad_norm(1.0, False), grad_norm(1e-2, False)
    bounded_big, bounded_small = grad_norm(1.0, True), grad_norm(1e-2, True)
    assert free_small[0] > 10 * free_big[0]  # the amplification the bounded form removes
    assert bounded_small[0] < 0.1 * bounded_big[0]
    for free, bounded in ((free_big, bounded_big), (free_small, bounded_small)):
        assert bounded[1] == pytest.approx(free[1] * (free[2] + 1e-8) ** 2, rel=1e-5)


def test_critic_gradient_reaches_psi_only_when_configured() -> None:
    """Same seed and batch: psi moves differently when the TD error trains it too."""
    system = SyntheticSystem(k=3)
    batch, pair = system.sample(8), system.sample(8)
    psi = {}
    for flag in (False, True):
        agent = make_agent(_config('zeus', critic_context_grad=flag, seed=3), system.spec())
        agent.update(batch, pair, 0)
        psi[flag] = [p.detach().clone() for p in agent.modules['psi'].parameters()]
    assert any(not torch.equal(a, b) for a, b in zip(psi[False], psi[True], strict=True))


def test_psi_target_trails_psi_and_feeds_the_td_target() -> None:
    """context_target_tau > 0: a slow copy of psi trails it and encodes H_{t+1}.

    It moves towards psi by tau per target update and takes no gradient; tau = 0: no copy.
    """
    system = SyntheticSystem(k=3)
    assert 'psi_target' not in make_agent(_config('zeus'), system.spec()).modules
    agent = make_agent(_config('zeus', context_target_tau=0.5, target_update_freq=1),
                       system.spec())
    psi, target = agent.modules['psi'], agent.modules['psi_target']
    assert not any(p.requires_grad for p in target.parameters())
    before = [p.detach().clone() for p in target.parameters()]
    batch, pair = system.sample(8), system.sample(8)
    agent.update(batch, pair, 0)
    for old, new, online in zip(before, target.parameters(), psi.parameters(), strict=True):
        torch.testing.assert_close(new, 0.5 * old + 0.5 * online.detach())
    metrics: dict[str, torch.Tensor] = {}
    losses = agent.objective.losses(agent, batch, pair, metrics)
    history, (feat, next_feat) = agent.history_features(
        batch.hist_obs, batch.hist_action, batch.hist_reward, batch.hist_next_obs,
        batch.hist_mask, batch.obs, batch.next_obs)
    next_history = history.detach().shifted(feat.detach(), agent.normalize_action(batch.action),
                                            batch.reward, next_feat.detach())
    with torch.no_grad():
        torch.testing.assert_close(losses.next_context, target(next_history))


def test_zero_context_input_init_starts_blind_and_learns_to_look() -> None:
    """context_input_init: zero: actor and critics ignore psi at first, not after updates.

    The feature columns start as usual (same seed: identical to the orthogonal init there).
    """
    system = SyntheticSystem(k=3)
    plain = make_agent(_config('zeus', seed=5), system.spec())
    agent = make_agent(_config('zeus', context_input_init='zero', seed=5), system.spec())
    context = slice(agent.config.feature_dim, agent.config.feature_dim + agent.context_dim)
    layers = [(a.modules[m].net if m == 'actor' else getattr(a.modules['critic'], m))[0].weight
              for a in (agent, plain) for m in ('actor', 'q1', 'q2')]
    zeroed, untouched = layers[:3], layers[3:]
    for weight, original in zip(zeroed, untouched, strict=True):
        assert torch.count_nonzero(weight[:, context]) == 0
        assert torch.count_nonzero(original[:, context]) > 0
        torch.testing.assert_close(weight[:, :context.start], original[:, :context.start])
    target = agent.modules['critic_target'].q1[0].weight
    assert torch.count_nonzero(target[:, context]) == 0
    for step in range(3):
        agent.update(system.sample(8), system.sample(8), step)
    assert all(torch.count_nonzero(w[:, context]) > 0 for w in zeroed)
    with pytest.raises(ConfigError, match='context_input_init'):
        _config('zeus', context_input_init='ones')


def test_old_checkpoints_keep_the_config_they_were_trained_with() -> None:
    """A stored config without the new fields gets the legacy values; 'oracle' was plain SAC."""
    stored = {**_config('oracle').to_dict()}
    for key in LEGACY_CONFIG:
        stored.pop(key)
    upgraded = config_from_dict(upgrade_stored_config(stored))
    assert upgraded.method == 'oracle_sac'
    assert upgraded.context_norm == 'none' and upgraded.context_loss == 'paper'
    assert not upgraded.critic_context_grad and upgraded.exploration == 'noise'
    current = _config('oracle').to_dict()
    assert upgrade_stored_config(current) == current


def _trace(obs: np.ndarray, psi: np.ndarray, context: float) -> Trace:
    n = len(obs)
    return Trace(reward=np.zeros(n), first=np.r_[True, np.zeros(n - 1, bool)],
                 context=np.full((n, 1), context), segment=np.zeros(n, int), psi=psi,
                 history_length=np.full(n, 3), obs=obs, action=np.zeros((n, 2), np.float32))


def test_sensitivity_is_zero_for_an_actor_blind_to_its_context() -> None:
    """Cutting the actor's context inputs makes the swap diagnostic exactly 0; otherwise > 0."""
    system = SyntheticSystem(k=3)
    agent = make_agent(_config('zeus', context_norm='none'), system.spec())
    rng = np.random.default_rng(0)
    obs = rng.standard_normal((20, *system.spec().obs_shape)).astype(np.float32)
    traces = [_trace(obs, rng.standard_normal((20, 4)).astype(np.float32) + shift, v)
              for shift, v in ((-3.0, 0.5), (0.0, 1.0), (3.0, 1.5))]
    values = [{'x': 0.5}, {'x': 1.0}, {'x': 1.5}]
    inference = InferenceAgent(agent)
    assert context_sensitivity(inference, traces, values) > 1e-3
    with torch.no_grad():
        first = next(agent.modules['actor'].parameters())
        first[:, -agent.context_dim:] = 0.0
    assert context_sensitivity(inference, traces, values) == 0.0
    blind = InferenceAgent(make_agent(_config('no_context'), system.spec()))
    assert np.isnan(context_sensitivity(blind, traces, values))


def test_spread_over_noise_and_extremes() -> None:
    """Known spreads and noise; the extremes and the farthest extreme of each value."""
    a = np.array([[0.0], [2.0]])  # mean 1, deviation 1
    b = np.array([[10.0], [12.0]])  # mean 11
    spread, noise, ratio = spread_over_noise([a, b])
    assert spread == pytest.approx(5.0) and noise == pytest.approx(1.0)
    assert ratio == pytest.approx(5.0)
    assert spread_over_noise([np.ones((3, 1)), np.zeros((3, 1))])[2] == float('inf')
    # true goals near 0.07 m through float32: rounding is not noise
    goals = [np.full((4, 2), g, np.float32) + np.float32(3e-7) * np.arange(4)[:, None]
             for g in (0.0714, 0.0742, -0.0755)]
    assert spread_over_noise(goals)[2] == float('inf')
    assert np.isnan(spread_over_noise([a, None])[2])
    values = [{'x': 1.0}, {'x': 0.2}, {'x': 3.0}, {'x': 2.5}]
    assert extreme_indices(values) == (1, 2)
    assert [farthest_extreme(values, i) for i in range(4)] == [2, 2, 1, 1]


def test_values_parse_any_values_and_name_mistakes() -> None:
    """Plain numbers for one parameter, name=value pairs for several; clear errors."""
    assert parse_values('0.5, 0.8,1.3', ['torso_length']) == [
        {'torso_length': 0.5}, {'torso_length': 0.8}, {'torso_length': 1.3}]
    assert parse_values('x=1:y=2', ['x', 'y']) == [{'x': 1.0, 'y': 2.0}]
    for text, names, match in (('a', ['t'], 'could not convert'), ('1', ['x', 'y'], 'x, y'),
                               ('x=1', ['x', 'y'], "'y'"), ('x=1:z=2', ['x'], 'unknown'),
                               ('', ['t'], 'at least one'), ('nan', ['t'], 'not finite')):
        with pytest.raises(ValueError, match=match):
            parse_values(text, names)
    values = [{'t': float(v)} for v in range(8)]
    shuffled = switching_order(values, 100)
    assert shuffled == switching_order(values, 100) and shuffled != values
    assert sorted(v['t'] for v in shuffled) == list(range(8))


def test_headroom_pairs_seeds_and_reports_the_share_recovered() -> None:
    """Gains are paired differences over common seeds; share = gain / headroom."""
    runs = []
    for seed, (nc, zeus, oracle) in enumerate([(10, 15, 20), (20, 24, 30), (30, 36, 40)]):
        runs += [{'method': 'no_context', 'seed': seed, 'split': 'train', 'mean_return': nc},
                 {'method': 'zeus', 'seed': seed, 'split': 'train', 'mean_return': zeus},
                 {'method': 'oracle', 'seed': seed, 'split': 'train', 'mean_return': oracle}]
    rows = {row['method']: row for row in headroom_rows(runs)}
    assert rows['zeus']['gain'] == pytest.approx(5.0)
    assert rows['zeus']['gain_se'] == pytest.approx(np.std([5, 4, 6], ddof=1) / np.sqrt(3))
    assert rows['zeus']['headroom'] == pytest.approx(10.0)
    assert rows['zeus']['recovered'] == pytest.approx(0.5)
    assert rows['oracle']['recovered'] == pytest.approx(1.0)


def test_consistency_loss_is_scale_free_and_zero_for_a_steady_context() -> None:
    """No drift gives 0; scaling psi leaves the loss unchanged; episode ends are ignored."""
    from zeus_ros.learning.representation import consistency_loss

    torch.manual_seed(0)
    psi = torch.randn(16, 4)
    not_done = torch.ones(16, 1)
    assert float(consistency_loss(psi, psi, not_done)) == 0.0
    noisy = psi + 0.1 * torch.randn(16, 4)
    loss = float(consistency_loss(psi, noisy, not_done))
    assert 0.0 < loss < 0.1
    shrunk = float(consistency_loss(psi * 1e-3, noisy * 1e-3, not_done))
    assert shrunk == pytest.approx(loss, rel=1e-2)
    ends = torch.zeros(16, 1)
    ends[0] = 1.0
    jumped = psi.clone()
    jumped[1:] += 100.0  # only the last steps of episodes jump: not counted
    assert float(consistency_loss(psi, jumped, ends)) == 0.0
