"""DrQ's random shift in the RL update (config.augment_shift): applied, consistent, and off by 0.

Why: route (b) of issue 36 (pixel RL sized for a CPU) trains the pixel agent with shifted
frames; with augment_shift 0 every earlier run must stay bit-identical (test_objectives.py pins
the losses by hash).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F  # noqa: N812

from zeus_ros.learning import ZeusConfig, make_agent
from zeus_ros.learning.augment import random_shift
from zeus_ros.learning.errors import ConfigError
from zeus_ros.learning.synthetic import SyntheticSystem

torch.set_num_threads(1)


def _config(**changes: object) -> ZeusConfig:
    base = dict(method='zeus', obs_kind='pixels', k=2, alpha_psi=1.0, hidden_dim=32,
                model_hidden_dim=16, context_hidden_dim=16, transition_dim=8, context_dim=4,
                feature_dim=8, num_filters=4, num_conv_layers=2, batch_size=4, device='cpu')
    base.update(changes)
    return ZeusConfig(**base)


def _train(config: ZeusConfig, updates: int = 3) -> tuple[list[dict[str, float]], dict]:
    """`updates` updates from the same init and batches; the metrics and final weights."""
    system = SyntheticSystem(k=config.k, pixels=True)
    agent = make_agent(config, system.spec())
    batches = [(system.sample(4), system.sample(4)) for _ in range(updates)]
    metrics = [agent.update(batch, pair, step) for step, (batch, pair) in enumerate(batches)]
    return metrics, {name: {k: v.clone() for k, v in m.state_dict().items()}
                     for name, m in agent.modules.items()}


def _same(a: dict, b: dict) -> bool:
    return all(torch.equal(a[n][k], b[n][k]) for n in a for k in a[n])


def test_random_shift_is_pad_and_crop() -> None:
    """Clamped indexing gives DrQ's replicate-pad-and-crop values, one offset per window."""
    stacks = torch.randint(0, 256, (5, 3, 9, 12, 12), dtype=torch.uint8)
    shifted = random_shift(stacks, 2, np.random.default_rng(7))
    dx, dy = np.random.default_rng(7).integers(0, 5, size=(2, 5))
    padded = F.pad(stacks.reshape(5, 27, 12, 12).float(), (2,) * 4, mode='replicate')
    expected = torch.stack([padded[i, :, dy[i]:dy[i] + 12, dx[i]:dx[i] + 12]
                            for i in range(5)]).reshape(stacks.shape)
    assert shifted.dtype == torch.uint8
    assert torch.equal(shifted.float(), expected)
    assert random_shift(stacks, 0, np.random.default_rng(7)) is stacks


def test_augment_keeps_each_window_consistent() -> None:
    """One shift per sample: the history still chains (o'_j = o_{j+1}) and ends at o_t."""
    system = SyntheticSystem(k=3, pixels=True, partial_fraction=0.0)
    agent = make_agent(_config(k=3, augment_shift=4), system.spec())
    batch = system.sample(6)
    out = agent.augment(batch)
    assert not torch.equal(out.obs, batch.obs)
    assert torch.equal(out.hist_next_obs[:, :-1], out.hist_obs[:, 1:])
    assert torch.equal(out.hist_next_obs[:, -1], out.obs)


@pytest.mark.slow
def test_augmented_updates_train_and_differ() -> None:
    """Pixel updates with the shift run, change the weights, and differ from unshifted ones."""
    system = SyntheticSystem(k=2, pixels=True)
    init = {name: {k: v.clone() for k, v in m.state_dict().items()}
            for name, m in make_agent(_config(augment_shift=4), system.spec()).modules.items()}
    metrics, weights = _train(_config(augment_shift=4))
    _, plain = _train(_config())
    assert all(np.isfinite(v) for row in metrics for v in row.values())
    assert not torch.equal(init['encoder']['fc.weight'], weights['encoder']['fc.weight'])
    assert not _same(weights, plain)


@pytest.mark.slow
def test_shift_zero_is_the_update_without_the_option() -> None:
    """augment_shift 0 trains exactly as a config that never names it (no RNG draw either)."""
    config = _config().to_dict()
    config.pop('augment_shift')
    metrics_absent, absent = _train(ZeusConfig(**config))
    metrics_zero, zero = _train(_config(augment_shift=0))
    assert metrics_zero == metrics_absent
    assert _same(zero, absent)


def test_shift_needs_pixels() -> None:
    """A shift on state vectors is refused, naming the field."""
    with pytest.raises(ConfigError, match='augment_shift'):
        ZeusConfig(obs_kind='state', augment_shift=4)
