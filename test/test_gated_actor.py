"""The novelty-gated actor of continual rounds and the per-sample behaviour-cloning anchor."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from zeus_ros.learning import ZeusConfig, load_checkpoint, make_agent, save_checkpoint
from zeus_ros.learning.gated_actor import GATE_QUANTILE, GATE_RAMP, GatedActor, fit_gate
from zeus_ros.learning.sac import Actor
from zeus_ros.learning.synthetic import SyntheticSystem

torch.set_num_threads(1)


def _agent(system: SyntheticSystem):
    config = ZeusConfig(method='zeus', obs_kind='state', k=3, hidden_dim=16,
                        model_hidden_dim=16, context_hidden_dim=16, encoder_hidden_dim=16,
                        transition_dim=8, context_dim=3, feature_dim=8, device='cpu',
                        actor_bc_weight=1.0, alpha_psi=1.0, adam_beta1=0.9)
    return make_agent(config, system.spec())


def _gated(context_dim: int = 2) -> GatedActor:
    torch.manual_seed(0)
    gated = GatedActor(Actor(4 + context_dim, 2, 16, -5.0, 2.0), context_dim, 2)
    gated.set_gate(np.array([[0.0, 0.0], [1.0, 1.0]]), scale=0.1, low=1.0, high=2.0)
    with torch.no_grad():  # the adapted copy differs from the deployed one
        for parameter in gated.adapted.parameters():
            parameter.add_(0.5)
    return gated


def test_familiar_contexts_act_as_deployed_and_novel_ones_as_adapted() -> None:
    """W = 0 within `low` of a centroid (the deployed actor exactly), 1 beyond `high`."""
    gated = _gated()
    feat = torch.randn(3, 4)
    near = torch.cat([feat, torch.tensor([[0.0, 0.05], [1.0, 1.0], [0.05, 0.0]])], -1)
    far = torch.cat([feat, torch.full((3, 2), 5.0)], -1)
    middle = torch.cat([feat, torch.tensor([[0.0, 0.15]] * 3)], -1)  # score 1.5: halfway
    base, adapted = gated.base(near), gated.adapted(far)
    torch.testing.assert_close(gated(near).mu, base.mu)
    torch.testing.assert_close(gated(near).log_std, base.log_std)
    torch.testing.assert_close(gated(far).mu, adapted.mu)
    torch.testing.assert_close(gated.weight(middle), torch.full((3, 1), 0.5))


def test_only_the_adapted_copy_learns_and_familiar_samples_teach_it_nothing() -> None:
    gated = _gated()
    near = torch.cat([torch.randn(4, 4), torch.zeros(4, 2)], -1)
    gated(near).mu.square().sum().backward()
    assert all(p.grad is None for p in gated.base.parameters())
    assert all(p.grad is None or not p.grad.any() for p in gated.adapted.parameters())
    far = torch.cat([torch.randn(4, 4), torch.full((4, 2), 5.0)], -1)
    gated(far).mu.square().sum().backward()
    assert any(p.grad is not None and p.grad.any() for p in gated.adapted.parameters())


def test_fit_gate_thresholds_on_the_train_contexts_own_spread() -> None:
    rng = np.random.default_rng(0)
    labels = np.repeat([0, 1], 500)
    contexts = np.where(labels[:, None] == 0, 0.0, 3.0) + 0.1 * rng.standard_normal((1000, 2))
    centroids, scale, low, high = fit_gate(contexts, labels)
    np.testing.assert_allclose(centroids, [[0, 0], [3, 3]], atol=0.02)
    distance = np.linalg.norm(contexts[:, None] - centroids[None], axis=2).min(1) / scale
    assert np.mean(distance <= low) == pytest.approx(GATE_QUANTILE, abs=0.002)
    assert high == pytest.approx(GATE_RAMP * low)
    with pytest.raises(ValueError, match='at least 10 steps per group'):
        fit_gate(contexts[:9], labels[:9])


def test_a_gated_agent_survives_its_checkpoint_and_trains_only_the_adapted_actor(
        tmp_path: Path) -> None:
    system = SyntheticSystem(k=3)
    agent = _agent(system)
    agent.gate_actor(np.zeros((2, 3)), 1.0, 1.0, 2.0)
    assert agent.config.actor_gate == 2
    base = {k: v.clone() for k, v in agent.modules['actor'].base.state_dict().items()}
    for step in range(4):
        agent.update(system.sample(8), system.sample(8), step)
    for key, value in agent.modules['actor'].base.state_dict().items():
        torch.testing.assert_close(value, base[key])  # the deployed actor never moves
    path = save_checkpoint(tmp_path / 'gated.pt', agent, step=4)
    loaded = load_checkpoint(path).agent
    assert isinstance(loaded.modules['actor'], GatedActor)
    b = system.sample(6)
    ctx = agent.encode_context(b.hist_obs, b.hist_action, b.hist_reward, b.hist_next_obs,
                               b.hist_mask)
    np.testing.assert_array_equal(loaded.act(b.obs, ctx), agent.act(b.obs, ctx))
    loaded.update(system.sample(8), system.sample(8), 5)  # its optimizer state fits
    with pytest.raises(ValueError, match='gated already'):
        loaded.gate_actor(np.zeros((2, 3)), 1.0, 1.0, 2.0)


def test_a_per_sample_anchor_equal_everywhere_is_the_single_weight() -> None:
    """The weighted anchor with every sample at w is the config's actor_bc_weight w."""
    system = SyntheticSystem(k=3)
    batch, pair = system.sample(16), system.sample(16)
    weighted = replace(batch, anchor=torch.full((16, 1), 1.0))
    results = []
    for b in (batch, weighted):
        torch.manual_seed(0)
        agent = _agent(system)
        results.append(agent.update(b, pair, 0)['loss/actor'])
    assert results[0] == pytest.approx(results[1], rel=1e-6)
    torch.manual_seed(0)
    zero = _agent(system).update(replace(batch, anchor=torch.zeros(16, 1)), pair, 0)
    assert zero['loss/actor'] != pytest.approx(results[0], rel=1e-3)
