"""Checkpoint round trip, resume state and validation errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from zeus_ros.learning import (
    CheckpointError,
    InferenceAgent,
    ZeusConfig,
    load_checkpoint,
    make_agent,
    save_checkpoint,
)
from zeus_ros.learning.synthetic import SyntheticSystem

torch.set_num_threads(1)


def _trained(tmp_path: Path, method: str = 'zeus', pixels: bool = False):
    system = SyntheticSystem(k=3, pixels=pixels)
    config = ZeusConfig(method=method, obs_kind='pixels' if pixels else 'state', k=3,
                        alpha_psi='auto', aggregation='max', hidden_dim=16,
                        model_hidden_dim=16, context_hidden_dim=16, encoder_hidden_dim=16,
                        transition_dim=8, context_dim=3, num_filters=4, num_conv_layers=2,
                        device='cpu')
    agent = make_agent(config, system.spec('Walker-Walk-v0'))
    for step in range(3):
        agent.update(system.sample(8), system.sample(8), step)
    path = save_checkpoint(tmp_path / 'agent.pt', agent, step=3, extra={'note': 'x', 'n': [1]})
    return system, agent, path


@pytest.mark.parametrize('pixels', [False, pytest.param(True, marks=pytest.mark.slow)])
def test_round_trip_gives_same_contexts_and_actions(tmp_path: Path, pixels: bool) -> None:
    """A reloaded agent computes the same contexts and actions."""
    system, agent, path = _trained(tmp_path, pixels=pixels)
    loaded = load_checkpoint(path, expect_task='Walker-Walk-v0')
    b = system.sample(4)
    args = (b.hist_obs, b.hist_action, b.hist_reward, b.hist_next_obs, b.hist_mask)
    ctx = agent.encode_context(*args)
    torch.testing.assert_close(loaded.agent.encode_context(*args), ctx)
    np.testing.assert_array_equal(loaded.agent.act(b.obs, ctx), agent.act(b.obs, ctx))
    assert loaded.step == 3 and loaded.extra == {'note': 'x', 'n': [1]}
    assert loaded.config.alpha_psi == 2.0 and loaded.config.aggregation == 'max'
    assert loaded.spec == agent.spec


def test_resume_restores_optimizer_state(tmp_path: Path) -> None:
    """Optimizer moments and the temperature survive the round trip."""
    _, agent, path = _trained(tmp_path)
    loaded = load_checkpoint(path).agent
    for name, opt in agent.optimizers.items():
        first = next(iter(opt.state_dict()['state'].values()))['exp_avg']
        again = next(iter(loaded.optimizers[name].state_dict()['state'].values()))['exp_avg']
        torch.testing.assert_close(first, again)
    assert loaded.log_alpha.item() == agent.log_alpha.item()


def test_task_mismatch_names_file_and_fields(tmp_path: Path) -> None:
    """Loading for another task and obs kind names the file, expected and found values."""
    _, _, path = _trained(tmp_path)
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(path, expect_task='Cheetah-Run-v0', expect_obs_kind='pixels')
    message = str(info.value)
    assert str(path) in message
    assert "expected 'Cheetah-Run-v0', found 'Walker-Walk-v0'" in message
    assert "obs_kind: expected 'pixels', found 'state'" in message


def test_missing_file_is_reported(tmp_path: Path) -> None:
    """A missing checkpoint raises CheckpointError naming the path."""
    with pytest.raises(CheckpointError, match='no such file'):
        load_checkpoint(tmp_path / 'nothing.pt')


def test_corrupt_file_is_reported(tmp_path: Path) -> None:
    """A truncated checkpoint raises CheckpointError, not a torch internals error."""
    _, _, path = _trained(tmp_path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match='unreadable or corrupt'):
        load_checkpoint(path)


def test_wrong_format_version_is_reported(tmp_path: Path) -> None:
    """A checkpoint of another format version is refused with both versions named."""
    _, _, path = _trained(tmp_path)
    payload = torch.load(path, weights_only=True)
    payload['format_version'] = 99
    torch.save(payload, path)
    with pytest.raises(CheckpointError, match='expected format_version 1, found 99'):
        load_checkpoint(path)


def test_mismatched_weights_are_reported(tmp_path: Path) -> None:
    """Weights that do not fit the stored shapes raise CheckpointError."""
    _, _, path = _trained(tmp_path)
    payload = torch.load(path, weights_only=True)
    payload['config']['hidden_dim'] = 32
    torch.save(payload, path)
    with pytest.raises(CheckpointError, match='do not fit'):
        load_checkpoint(path)


def test_extra_must_be_plain_data(tmp_path: Path) -> None:
    """Objects in `extra` are refused at save time (they could not be loaded safely)."""
    _, agent, _ = _trained(tmp_path)
    with pytest.raises(TypeError, match=r'extra\.obj'):
        save_checkpoint(tmp_path / 'bad.pt', agent, step=0, extra={'obj': object()})


def test_inference_agent_loads_checkpoint(tmp_path: Path) -> None:
    """InferenceAgent.from_checkpoint exposes what the nodes need."""
    _, _, path = _trained(tmp_path)
    inference = InferenceAgent.from_checkpoint(path, expect_task='Walker-Walk-v0',
                                               expect_obs_kind='state')
    assert (inference.k, inference.obs_shape, inference.context_dim) == (3, (6,), 3)
    assert inference.context_names == ('gain',) and inference.task == 'Walker-Walk-v0'
    assert np.all(inference.action_low == -1.0) and np.all(inference.action_high == 1.0)


@pytest.mark.parametrize('method', ['zeus', 'no_context', 'cadm'])
def test_deployment_export_acts_like_the_original_and_is_smaller(tmp_path: Path,
                                                                 method: str) -> None:
    """The export keeps phi, psi and the actor: same contexts and actions, far fewer bytes."""
    from zeus_ros.learning.checkpoint import export_for_deployment

    system, agent, path = _trained(tmp_path, method=method)
    small = export_for_deployment(path, tmp_path / 'deploy.pt')
    loaded = load_checkpoint(small, expect_task='Walker-Walk-v0')
    assert loaded.deploy and not load_checkpoint(path).deploy
    assert loaded.step == 3 and loaded.extra == {'note': 'x', 'n': [1]}
    b = system.sample(4)
    args = (b.hist_obs, b.hist_action, b.hist_reward, b.hist_next_obs, b.hist_mask)
    ctx = agent.encode_context(*args)
    torch.testing.assert_close(loaded.agent.encode_context(*args), ctx)
    np.testing.assert_array_equal(loaded.agent.act(b.obs, ctx), agent.act(b.obs, ctx))
    assert small.stat().st_size < path.stat().st_size / 3
    stored = torch.load(small, weights_only=True)['state']
    assert set(stored['modules']) <= {'encoder', 'psi', 'context_norm', 'actor'}
    assert not stored['optimizers']
    # exporting again, under another name, gives the same bytes (the card's sha256 holds)
    again = export_for_deployment(path, tmp_path / 'other_name.pt')
    assert again.read_bytes() == small.read_bytes()


def test_acting_only_load_has_no_optimizers_and_refuses_to_train(tmp_path: Path) -> None:
    """load_optimizers=False: same actions, no Adam state, and update says how to train."""
    system, agent, path = _trained(tmp_path)
    loaded = load_checkpoint(path, load_optimizers=False)
    assert loaded.agent.optimizers == {}
    b = system.sample(4)
    args = (b.hist_obs, b.hist_action, b.hist_reward, b.hist_next_obs, b.hist_mask)
    ctx = agent.encode_context(*args)
    np.testing.assert_array_equal(loaded.agent.act(b.obs, ctx), agent.act(b.obs, ctx))
    with pytest.raises(RuntimeError, match='load the checkpoint with its optimizers'):
        loaded.agent.update(system.sample(8), system.sample(8), 3)
    assert load_checkpoint(path).agent.optimizers  # the default still resumes training
