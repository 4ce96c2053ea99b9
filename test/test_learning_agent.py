"""Every method trains without NaNs, losses fall, and inference helpers behave."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from zeus_ros.learning import METHODS, ZeusConfig, make_agent
from zeus_ros.learning.synthetic import SyntheticSystem

torch.set_num_threads(1)


def _config(method: str, obs_kind: str = 'state', **changes: object) -> ZeusConfig:
    base = dict(method=method, obs_kind=obs_kind, k=3, alpha_psi=1.0, hidden_dim=32,
                model_hidden_dim=32, context_hidden_dim=32, encoder_hidden_dim=32,
                transition_dim=8, context_dim=4, num_filters=4, num_conv_layers=2,
                batch_size=8, device='cpu')
    base.update(changes)
    return ZeusConfig(**base)


@pytest.mark.parametrize('method', METHODS)
def test_state_updates_are_finite(method: str) -> None:
    """A few updates of each method on state batches give finite metrics and weights."""
    system = SyntheticSystem(k=3)
    agent = make_agent(_config(method), system.spec())
    for step in range(4):
        metrics = agent.update(system.sample(8), system.sample(8), step)
        assert metrics and all(math.isfinite(v) for v in metrics.values())
    assert 'loss/critic' in metrics
    for module in agent.modules.values():
        assert all(torch.isfinite(p).all() for p in module.parameters())


@pytest.mark.parametrize('method', METHODS)
def test_pixel_updates_are_finite(method: str) -> None:
    """A tiny pixel agent of each method runs two updates without NaNs."""
    system = SyntheticSystem(k=2, pixels=True)
    agent = make_agent(_config(method, 'pixels', k=2), system.spec())
    for step in range(2):
        metrics = agent.update(system.sample(4), system.sample(4), step)
        assert all(math.isfinite(v) for v in metrics.values())
    assert 'loss/reconstruction' in metrics


@pytest.mark.parametrize(('method', 'keys'), [
    ('zeus', {'loss/context', 'loss/dynamics', 'loss/reward'}),
    ('zeus_no_context_loss', {'loss/dynamics', 'loss/reward'}),
    ('cadm', {'loss/dynamics', 'loss/backward_dynamics'}),
    ('up_osi', {'loss/osi'}),
])
def test_methods_report_their_losses(method: str, keys: set[str]) -> None:
    """Each method reports its representation losses; only zeus has a context loss."""
    system = SyntheticSystem(k=3)
    metrics = make_agent(_config(method), system.spec()).update(
        system.sample(8), system.sample(8), 0)
    assert keys <= set(metrics)
    assert ('loss/context' in metrics) == (method == 'zeus')
    assert {'loss/actor', 'train/alpha'} <= set(metrics)


def test_context_dims_per_method() -> None:
    """no_context has no context; up_osi and oracle use the number of true parameters."""
    spec = SyntheticSystem().spec()
    dims = {m: make_agent(_config(m), spec).context_dim for m in METHODS}
    assert dims == {'zeus': 4, 'zeus_no_context_loss': 4, 'no_context': 0, 'up_osi': 1,
                    'cadm': 4, 'oracle': 1, 'oracle_sac': 1}


def test_zeus_requires_pair_batch() -> None:
    """ZeUS without a pair batch fails with a clear message."""
    system = SyntheticSystem(k=3)
    agent = make_agent(_config('zeus'), system.spec())
    with pytest.raises(ValueError, match='pair'):
        agent.update(system.sample(8), None, 0)


def test_batch_with_wrong_k_is_rejected() -> None:
    """A batch built for another history length names the field and shapes."""
    system = SyntheticSystem(k=4)
    agent = make_agent(_config('zeus'), SyntheticSystem(k=3).spec())
    with pytest.raises(ValueError, match='hist_obs'):
        agent.update(system.sample(8), system.sample(8), 0)


@pytest.mark.slow
def test_model_losses_fall_on_synthetic_system() -> None:
    """Dynamics and reward losses drop over a short ZeUS training on the synthetic system."""
    system = SyntheticSystem(k=3, seed=1)
    agent = make_agent(_config('zeus', hidden_dim=64, model_hidden_dim=64, batch_size=64),
                       system.spec())
    history = []
    for step in range(150):
        history.append(agent.update(system.sample(64), system.sample(64), step))
    first = {k: np.mean([h[k] for h in history[:10]]) for k in ('loss/dynamics', 'loss/reward')}
    last = {k: np.mean([h[k] for h in history[-10:]]) for k in ('loss/dynamics', 'loss/reward')}
    assert last['loss/dynamics'] < first['loss/dynamics']
    assert last['loss/reward'] < 0.5 * first['loss/reward']


@pytest.mark.slow
def test_up_osi_regression_loss_falls() -> None:
    """UP-OSI's psi learns to regress the true context."""
    system = SyntheticSystem(k=3, seed=2, partial_fraction=0.0)
    agent = make_agent(_config('up_osi', batch_size=64), system.spec())
    losses = [agent.update(system.sample(64), None, step)['loss/osi'] for step in range(120)]
    assert np.mean(losses[-10:]) < 0.5 * np.mean(losses[:10])


def test_up_osi_warmup_uses_true_context() -> None:
    """UP-OSI conditions on the true context only during its warm-up updates."""
    agent = make_agent(_config('up_osi', num_updates=1000, up_osi_warmup_fraction=0.01),
                       SyntheticSystem().spec())
    assert agent.uses_true_context(0) and agent.uses_true_context(9)
    assert not agent.uses_true_context(10)


def test_act_in_bounds_single_and_batched() -> None:
    """act() returns actions inside the task bounds for one and for many observations."""
    system = SyntheticSystem(k=3)
    spec = system.spec()
    agent = make_agent(_config('zeus'), spec)
    batch = system.sample(5)
    context = agent.encode_context(batch.hist_obs, batch.hist_action, batch.hist_reward,
                                   batch.hist_next_obs, batch.hist_mask)
    many = agent.act(batch.obs.numpy(), context, deterministic=False)
    one = agent.act(batch.obs[0].numpy(), context[0])
    assert many.shape == (5, 2) and one.shape == (2,)
    assert np.all(np.abs(many) <= 1.0) and np.all(np.abs(one) <= 1.0)


def test_encode_context_single_matches_batched() -> None:
    """An unbatched history gives the same context as the same row of a batch."""
    system = SyntheticSystem(k=3)
    agent = make_agent(_config('zeus'), system.spec())
    b = system.sample(3)
    batched = agent.encode_context(b.hist_obs, b.hist_action, b.hist_reward, b.hist_next_obs,
                                   b.hist_mask)
    single = agent.encode_context(b.hist_obs[1], b.hist_action[1], b.hist_reward[1],
                                  b.hist_next_obs[1], b.hist_mask[1])
    torch.testing.assert_close(single, batched[1])


def test_chained_history_shortcut_matches_full_encoding() -> None:
    """The k + 1 frame shortcut gives phi(o'_j) of every real slot, as encoding all 2k would."""
    system = SyntheticSystem(k=3, partial_fraction=0.5)
    agent = make_agent(_config('zeus'), system.spec())
    b = system.sample(16)
    with torch.no_grad():
        history, _ = agent.history_features(b.hist_obs, b.hist_action, b.hist_reward,
                                            b.hist_next_obs, b.hist_mask)
        direct = agent.modules['encoder'](b.hist_next_obs.flatten(0, 1)).view(16, 3, -1)
    real = b.hist_mask
    assert real.any() and not real.all()
    torch.testing.assert_close(history.next_feat[real], direct[real])


def test_unchained_history_encodes_every_next_frame() -> None:
    """A history whose o'_j is not o_{j+1} falls back to encoding each next frame."""
    system = SyntheticSystem(k=3, partial_fraction=0.0)
    agent = make_agent(_config('zeus'), system.spec())
    b = system.sample(8)
    b.hist_next_obs[:, 0] += 0.5
    with torch.no_grad():
        history, _ = agent.history_features(b.hist_obs, b.hist_action, b.hist_reward,
                                            b.hist_next_obs, b.hist_mask)
        direct = agent.modules['encoder'](b.hist_next_obs.flatten(0, 1)).view(8, 3, -1)
    torch.testing.assert_close(history.next_feat, direct)


@pytest.mark.parametrize('method', ['zeus', 'oracle', 'no_context'])
def test_frozen_representation_trains_only_actor_and_critic(method: str) -> None:
    """Frozen from update 2: phi, psi and the models keep their weights, actor and critic learn.

    The representation losses are still logged (computed without gradient).
    """
    system = SyntheticSystem(k=3)
    agent = make_agent(_config(method, representation_frozen_from=2), system.spec())
    for step in range(2):
        agent.update(system.sample(8), system.sample(8), step)
    frozen = {name: [p.detach().clone() for p in agent.modules[name].parameters()]
              for name in ('encoder', 'psi', 'transition', 'reward') if name in agent.modules}
    heads = {name: [p.detach().clone() for p in agent.modules[name].parameters()]
             for name in ('actor', 'critic')}
    for step in range(2, 6):
        metrics = agent.update(system.sample(8), system.sample(8), step)
    assert 'loss/critic' in metrics
    assert ('loss/representation' in metrics) == agent.has_representation_step
    for name, before in frozen.items():
        after = list(agent.modules[name].parameters())
        assert all(torch.equal(a, b) for a, b in zip(after, before, strict=True)), name
    for name, before in heads.items():
        after = list(agent.modules[name].parameters())
        assert not all(torch.equal(a, b) for a, b in zip(after, before, strict=True)), name


def test_representation_frozen_from_must_be_a_count() -> None:
    """A negative or non-integer start is named in the error."""
    from zeus_ros.learning.config import ConfigError

    for bad in (-1, 2.5, True):
        with pytest.raises(ConfigError, match='representation_frozen_from'):
            _config('zeus', representation_frozen_from=bad)


@pytest.mark.parametrize('method', ['zeus', 'cadm', 'oracle'])
def test_observation_model_target_predicts_the_state_change(method: str) -> None:
    """model_target 'observation': T (and CaDM's backward model) predict (o' - o) / obs_std.

    The dynamics loss is recomputed by hand from the agent's own modules: the same number means
    the target is the normalised state change, not phi(o').
    """
    from zeus_ros.learning.models import gaussian_nll

    system = SyntheticSystem(k=3)
    agent = make_agent(_config(method, model_target='observation'), system.spec())
    obs_dim = system.spec().obs_shape[0]
    for name in ('transition', 'backward'):
        if name in agent.modules:
            assert agent.modules[name].mu.out_features == obs_dim, name
    for step in range(3):
        metrics = agent.update(system.sample(8), system.sample(8), step)
        assert all(math.isfinite(v) for v in metrics.values())
    batch = system.sample(8)
    metrics = {}
    with torch.no_grad():
        agent.objective.losses(agent, batch, system.sample(8), metrics)
        m = agent.modules
        feat = m['encoder'](batch.obs)
        action = agent.normalize_action(batch.action)
        if method == 'oracle':
            context = agent.policy_context(batch.context.float())
        else:
            history, _ = agent.history_features(batch.hist_obs, batch.hist_action,
                                                batch.hist_reward, batch.hist_next_obs,
                                                batch.hist_mask)
            context = m['psi'](history)
        change = (batch.next_obs - batch.obs) / m['encoder'].obs_std
        expected = gaussian_nll(m['transition'](feat, action, context), change)
    torch.testing.assert_close(metrics['loss/dynamics'], expected)


def test_observation_model_target_needs_state_observations() -> None:
    """Pixels have no state vector to predict: the error names the field and the way out."""
    from zeus_ros.learning.config import ConfigError

    with pytest.raises(ConfigError, match=r"model_target 'observation'.*'latent'"):
        _config('zeus', 'pixels', model_target='observation')
