"""psi aggregation masking, eq. 1 context loss and its stopped gradients."""

from __future__ import annotations

import pytest
import torch

from zeus_ros.learning import AGGREGATIONS, ZeusConfig, make_agent
from zeus_ros.learning.context import ContextEncoder, HistoryFeatures, aggregate
from zeus_ros.learning.models import RewardModel, TransitionModel
from zeus_ros.learning.representation import context_loss
from zeus_ros.learning.synthetic import SyntheticSystem

torch.set_num_threads(1)
B, K, F, A = 4, 5, 8, 2


def _history(mask: torch.Tensor, seed: int = 0) -> HistoryFeatures:
    g = torch.Generator().manual_seed(seed)
    return HistoryFeatures(
        feat=torch.randn(B, K, F, generator=g), action=torch.rand(B, K, A, generator=g) * 2 - 1,
        reward=torch.randn(B, K, 1, generator=g), next_feat=torch.randn(B, K, F, generator=g),
        mask=mask)


def _partial_mask() -> torch.Tensor:
    counts = torch.tensor([0, 1, 3, 5])
    return torch.arange(K).unsqueeze(0) >= (K - counts).unsqueeze(1)


def _tiny_zeus(alpha_psi: float = 1.0):
    system = SyntheticSystem(k=3)
    config = ZeusConfig(method='zeus', k=3, alpha_psi=alpha_psi, hidden_dim=16,
                        model_hidden_dim=16, context_hidden_dim=16, encoder_hidden_dim=16,
                        transition_dim=8, context_dim=4, device='cpu')
    return system, make_agent(config, system.spec())


@pytest.mark.parametrize('operator', AGGREGATIONS)
def test_masked_slots_do_not_change_psi(operator: str) -> None:
    """Changing the content of masked history slots leaves psi unchanged."""
    psi = ContextEncoder(F, A, K, context_dim=3, aggregation=operator, transition_dim=6,
                         hidden_dim=16)
    mask = _partial_mask()
    first, second = _history(mask, seed=1), _history(mask, seed=2)
    for name in ('feat', 'action', 'reward', 'next_feat'):
        real = getattr(first, name)
        getattr(second, name)[mask] = real[mask]
    assert not torch.equal(first.feat, second.feat)
    torch.testing.assert_close(psi(first), psi(second))


@pytest.mark.parametrize('operator', AGGREGATIONS)
def test_all_masked_history_gives_finite_psi(operator: str) -> None:
    """An empty history (first step of an episode) gives a finite context."""
    psi = ContextEncoder(F, A, K, context_dim=3, aggregation=operator)
    history = _history(torch.zeros(B, K, dtype=torch.bool))
    history.feat.fill_(1e30)
    out = psi(history)
    assert out.shape == (B, 3)
    assert torch.isfinite(out).all()


def _speed_target_histories(generator: torch.Generator, n: int, k: int = 8
                            ) -> tuple[HistoryFeatures, torch.Tensor]:
    """Cheetah-Run-v1 in one dimension: speeds v_j and rewards -|v_j - target|."""
    target = torch.rand(n, 1, generator=generator) * 3
    speed = torch.rand(n, k, 1, generator=generator) * 4
    reward = -(speed - target.unsqueeze(1)).abs()
    return HistoryFeatures(speed, torch.zeros(n, k, 1), reward, speed,
                           torch.ones(n, k, dtype=torch.bool)), target


@pytest.mark.slow
def test_mlp_head_combines_transitions_a_linear_head_can_only_average() -> None:
    """A nonlinear head after the mean finds the target every transition allows.

    Each |v - target| allows two targets; keeping the one all transitions agree on needs Deep
    Sets' rho. Same codes, same training: the MLP head's error is under half the linear head's
    (0.15-0.31 of it over seeds 0-3).
    """
    errors = {}
    for head in ('linear', 'mlp'):
        torch.manual_seed(0)
        generator = torch.Generator().manual_seed(0)
        psi = ContextEncoder(1, 1, 8, context_dim=1, aggregation='mean', transition_dim=16,
                             hidden_dim=32, head=head)
        optimizer = torch.optim.Adam(psi.parameters(), lr=3e-3)
        for _ in range(600):
            history, target = _speed_target_histories(generator, 128)
            loss = ((psi(history) - target) ** 2).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        history, target = _speed_target_histories(generator, 2048)
        with torch.no_grad():
            errors[head] = float(((psi(history) - target) ** 2).mean())
    assert errors['mlp'] < 0.5 * errors['linear'], errors
    with pytest.raises(ValueError, match='linear, mlp'):
        ContextEncoder(1, 1, 8, context_dim=1, head='attention')


def test_mean_divides_by_number_of_real_slots() -> None:
    """Mean aggregation averages over real transitions only."""
    codes = torch.tensor([[[9.0], [2.0], [4.0]]])
    mask = torch.tensor([[False, True, True]])
    assert aggregate(codes, mask, 'mean').item() == pytest.approx(3.0)


def test_min_max_product_use_neutral_fill() -> None:
    """min/max/product ignore masked slots even when those hold extreme values."""
    codes = torch.tensor([[[-7.0], [0.5], [0.25]]])
    mask = torch.tensor([[False, True, True]])
    assert aggregate(codes, mask, 'min').item() == pytest.approx(0.25)
    assert aggregate(codes, mask, 'max').item() == pytest.approx(0.5)
    assert aggregate(codes, mask, 'product').item() == pytest.approx(0.125)


def test_shifted_history_appends_current_transition() -> None:
    """H_{t+1} drops the oldest slot, appends the transition and marks it real."""
    history = _history(_partial_mask())
    new = torch.full((B, F), 3.0)
    nxt = history.shifted(new, torch.zeros(B, A), torch.ones(B, 1), new + 1)
    torch.testing.assert_close(nxt.feat[:, :-1], history.feat[:, 1:])
    assert torch.equal(nxt.feat[:, -1], new)
    assert nxt.mask[:, -1].all()
    assert torch.equal(nxt.mask[:, :-1], history.mask[:, 1:])


def test_context_loss_zero_for_identical_histories() -> None:
    """Identical contexts give zero psi distance, zero d and zero loss."""
    transition, reward = TransitionModel(F, A, 3, 16), RewardModel(F, A, 3, 16)
    psi1 = torch.randn(B, 3, requires_grad=True)
    out = context_loss(transition, reward, torch.randn(B, F), torch.zeros(B, A), psi1,
                       psi1.clone())
    assert out.loss.item() == 0.0
    out.loss.backward()
    assert torch.isfinite(psi1.grad).all()


def test_task_distance_grows_with_context_distance() -> None:
    """d(c1, c2) from T and R grows as psi(H2) moves away from psi(H1)."""
    torch.manual_seed(0)
    transition, reward = TransitionModel(F, A, 3, 32), RewardModel(F, A, 3, 32)
    feat, action = torch.randn(B, F), torch.zeros(B, A)
    psi1 = torch.zeros(B, 3)
    direction = torch.ones(B, 3)
    distances = [context_loss(transition, reward, feat, action, psi1, psi1 + s * direction)
                 .task_distance.mean().item() for s in (0.0, 0.5, 2.0)]
    assert distances[0] == 0.0
    assert distances[0] < distances[1] < distances[2]


def test_context_loss_gives_no_gradient_to_t_and_r() -> None:
    """T and R parameters receive no gradient from the context loss; psi does."""
    transition, reward = TransitionModel(F, A, 3, 16), RewardModel(F, A, 3, 16)
    psi1 = torch.randn(B, 3, requires_grad=True)
    psi2 = torch.randn(B, 3, requires_grad=True)
    feat = torch.randn(B, F, requires_grad=True)
    out = context_loss(transition, reward, feat, torch.zeros(B, A), psi1, psi2)
    out.loss.backward()
    assert all(p.grad is None for p in [*transition.parameters(), *reward.parameters()])
    assert feat.grad is None
    assert psi1.grad is not None and psi1.grad.abs().sum() > 0


def test_dynamics_target_gets_no_gradient() -> None:
    """phi(o') is a stopped target: the representation loss sends no gradient to next_obs."""
    system, agent = _tiny_zeus(alpha_psi=0.0)
    batch = system.sample(8)
    batch.next_obs.requires_grad_(True)
    batch.obs.requires_grad_(True)
    losses = agent.objective.losses(agent, batch, None, {})
    losses.total.backward()
    assert batch.next_obs.grad is None or batch.next_obs.grad.abs().sum() == 0
    assert batch.obs.grad is not None and batch.obs.grad.abs().sum() > 0


def test_representation_step_trains_t_r_only_through_model_losses() -> None:
    """With only the context loss active, T and R get no gradient but psi does."""
    system, agent = _tiny_zeus()
    batch, pair = system.sample(8), system.sample(8)
    metrics: dict[str, torch.Tensor] = {}
    agent.objective.losses(agent, batch, pair, metrics)
    metrics['loss/context'].backward()
    for name in ('transition', 'reward'):
        assert all(p.grad is None for p in agent.modules[name].parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0
               for p in agent.modules['psi'].parameters())


def test_models_predict_the_sampled_transition_ahead() -> None:
    """T and R are fit on the batch's model transition when it carries one (model_horizon)."""
    system, agent = _tiny_zeus(alpha_psi=0.0)
    batch = system.sample(16)
    torch.manual_seed(0)
    plain: dict[str, torch.Tensor] = {}
    agent.objective.losses(agent, batch, None, plain)
    batch.model_obs, batch.model_action = batch.obs, batch.action
    batch.model_reward, batch.model_next_obs = batch.reward, batch.next_obs
    same: dict[str, torch.Tensor] = {}
    agent.objective.losses(agent, batch, None, same)
    assert torch.allclose(same['loss/reward'], plain['loss/reward'])
    assert torch.allclose(same['loss/dynamics'], plain['loss/dynamics'])
    batch.model_reward = batch.reward + 10.0
    moved: dict[str, torch.Tensor] = {}
    agent.objective.losses(agent, batch, None, moved)
    assert moved['loss/reward'] > plain['loss/reward'] + 50.0
    assert torch.allclose(moved['loss/dynamics'], plain['loss/dynamics'])


def test_code_norm_keeps_psi_alive_where_the_tanh_saturates() -> None:
    """Blown-up pre-activations (as in the collapsed Cheetah-Motor-v0 runs).

    Without code_norm every code is +-1, psi is the same for different histories and no
    gradient reaches the per-transition MLP; with it psi still tells them apart and learns.
    """
    full = torch.ones(B, K, dtype=torch.bool)
    first, second = _history(full, seed=1), _history(full, seed=2)
    for code_norm, alive in ((False, False), (True, True)):
        torch.manual_seed(0)
        psi = ContextEncoder(F, A, K, context_dim=3, transition_dim=8, hidden_dim=16,
                             code_norm=code_norm)
        with torch.no_grad():
            last = psi.transition[-1]
            last.weight.mul_(1e3)
            last.bias.fill_(1e6)  # every history's pre-activations far out on the same side
        gap = (psi(first) - psi(second)).abs().max().detach()
        psi(first).pow(2).sum().backward()
        grad = last.weight.grad.abs().max()
        assert (float(gap) > 1e-3) is alive, code_norm
        assert (float(grad) > 1e-6) is alive, code_norm
