"""The update's shortcuts (issue 51) compute what the long way computes.

psi(H_{t+1}) from H_t's kept codes and eq. 1's d from the dynamics and reward losses' own
predictions are only speed: these pin them to the full computations they replace.
"""

from __future__ import annotations

import pytest
import torch

from zeus_ros.learning import AGGREGATIONS
from zeus_ros.learning.context import ContextEncoder, HistoryFeatures
from zeus_ros.learning.models import RewardModel, TransitionModel
from zeus_ros.learning.representation import context_loss

torch.set_num_threads(1)
B, K, F, A = 6, 5, 8, 2


def _history(seed: int = 0) -> HistoryFeatures:
    g = torch.Generator().manual_seed(seed)
    counts = torch.tensor([0, 1, 3, 5, 5, 2])  # empty, partial and full histories
    return HistoryFeatures(
        feat=torch.randn(B, K, F, generator=g), action=torch.rand(B, K, A, generator=g) * 2 - 1,
        reward=torch.randn(B, K, 1, generator=g), next_feat=torch.randn(B, K, F, generator=g),
        mask=torch.arange(K).unsqueeze(0) >= (K - counts).unsqueeze(1))


@pytest.mark.parametrize('code_norm', [False, True])
@pytest.mark.parametrize('aggregation', AGGREGATIONS)
def test_shifted_context_from_codes_matches_the_shifted_history(aggregation: str,
                                                                code_norm: bool) -> None:
    torch.manual_seed(0)
    psi = ContextEncoder(F, A, K, 3, aggregation, 16, 32, 'mlp', code_norm)
    history = _history()
    g = torch.Generator().manual_seed(1)
    new = (torch.randn(B, F, generator=g), torch.rand(B, A, generator=g),
           torch.randn(B, 1, generator=g), torch.randn(B, F, generator=g))
    expected = psi(history.shifted(*new))
    found = psi.shifted(psi.codes(history), history.mask, *new)
    torch.testing.assert_close(found, expected, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize('use_sigma', [False, True])
def test_context_loss_with_the_models_predictions_matches_recomputing_them(
        use_sigma: bool) -> None:
    torch.manual_seed(0)
    transition, reward = TransitionModel(F, A, 3, 16), RewardModel(F, A, 3, 16)
    feat, action = torch.randn(B, F, requires_grad=True), torch.rand(B, A) * 2 - 1
    psi1, psi2 = torch.randn(B, 3, requires_grad=True), torch.randn(B, 3, requires_grad=True)
    full = context_loss(transition, reward, feat, action, psi1, psi2, use_sigma=use_sigma,
                        scale_free=True)
    reused = context_loss(transition, reward, feat, action, psi1, psi2, use_sigma=use_sigma,
                          scale_free=True, at_psi1=(reward(feat, action, psi1),
                                                    transition(feat, action, psi1)))
    torch.testing.assert_close(reused.loss, full.loss, rtol=1e-6, atol=1e-7)
    torch.testing.assert_close(reused.task_distance, full.task_distance, rtol=1e-6, atol=1e-7)
    grads = [torch.autograd.grad(out.loss, (psi1, psi2)) for out in (full, reused)]
    for want, got in zip(*grads, strict=True):
        torch.testing.assert_close(got, want, rtol=1e-6, atol=1e-7)
