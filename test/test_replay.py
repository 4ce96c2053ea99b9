"""ReplayBuffer: histories stay inside episodes, masks and contents match the dataset."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from zeus_ros.offline.data.ingest import Dataset, Episode, IngestReport
from zeus_ros.offline.data.replay import ReplayBuffer

OBS_DIM = 3
ACT_DIM = 2


def _episode(ep: int, first_step: int, length: int, *, frames: bool = False) -> Episode:
    """An episode whose values encode (episode, step) so any sample can be traced back."""
    steps = np.arange(first_step, first_step + length + 1)
    obs = np.stack([steps * 1.0, np.full_like(steps, ep) * 1.0, steps % 7 * 0.5], 1)
    pix = None
    if frames:
        pix = np.zeros((length + 1, 3, 84, 84), np.uint8)
        pix[:, 0, 0, 0] = steps % 256
        pix[:, 1, 0, 0] = ep
    return Episode(
        source='synthetic', episode=ep, steps=steps, stamps_ns=steps * 10,
        obs=obs, frames=pix,
        action=np.stack([steps[:-1] + 0.25, -steps[:-1] * 1.0], 1).astype(np.float32),
        action_status=np.ones(length, np.uint8),
        policy_action=np.zeros((length + 1, ACT_DIM), np.float32),
        reward=steps[:-1] + 0.5,
        first=np.arange(length + 1) == 0, last=np.arange(length + 1) == length,
        episode_step=np.arange(length + 1),
        context=np.stack([steps * 0.1], 1), segment=np.zeros(length + 1, np.int64),
    )


def _dataset(lengths: list[int], *, frames: bool = False) -> Dataset:
    eps, step = [], 0
    for i, n in enumerate(lengths):
        eps.append(_episode(i, step, n, frames=frames))
        step += n + 1
    return Dataset(task='Synthetic-v0', context_names=('c',), episodes=eps,
                   report=IngestReport())


def test_histories_match_previous_transitions_and_masks() -> None:
    """Every history slot equals the dataset's transition j=t-k+m or is masked and zero."""
    data = _dataset([3, 10, 1, 6])
    buf = ReplayBuffer(data, history=4, seed=1)
    b = buf.sample(512)
    step = b.obs[:, 0].numpy().astype(int)
    ep = b.obs[:, 1].numpy().astype(int)
    starts = {i: int(e.steps[0]) for i, e in enumerate(data.episodes)}
    for i in range(b.batch_size):
        t, first = step[i], starts[ep[i]]
        for m in range(4):
            j = t - 4 + m
            assert bool(b.hist_mask[i, m]) == (j >= first)
            if j >= first:
                assert b.hist_obs[i, m, 0] == j and b.hist_obs[i, m, 1] == ep[i]
                assert b.hist_next_obs[i, m, 0] == j + 1
                assert b.hist_action[i, m, 0] == pytest.approx(j + 0.25)
                assert b.hist_reward[i, m, 0] == pytest.approx(j + 0.5)
            else:
                assert not b.hist_obs[i, m].any() and not b.hist_action[i, m].any()
                assert not b.hist_reward[i, m].any() and not b.hist_next_obs[i, m].any()


def test_transition_fields_align() -> None:
    """o_t, a_t, r_{t+1}, o_{t+1} and c_{t+1} come from the same step of the same episode."""
    buf = ReplayBuffer(_dataset([5, 8]), history=2, seed=3)
    b = buf.sample(256)
    t = b.obs[:, 0]
    assert torch.equal(b.next_obs[:, 0], t + 1)
    assert torch.equal(b.next_obs[:, 1], b.obs[:, 1])
    assert torch.allclose(b.action[:, 0], t + 0.25)
    assert torch.allclose(b.reward[:, 0], t + 0.5)
    assert torch.allclose(b.context[:, 0], (t + 1) * 0.1)
    assert torch.equal(b.not_done, torch.ones_like(b.not_done))


def test_never_samples_across_episode_end() -> None:
    """No sampled transition starts at an episode's last observation."""
    data = _dataset([2, 2, 2])
    buf = ReplayBuffer(data, history=3, seed=0)
    lasts = {int(e.steps[-1]) for e in data.episodes}
    b = buf.sample(1000)
    assert not set(b.obs[:, 0].int().tolist()) & lasts
    assert len(buf) == 6


def test_seeded_sampling_repeats() -> None:
    """Two buffers with the same seed draw the same batches."""
    a = ReplayBuffer(_dataset([5, 5]), history=2, seed=7).sample(32)
    b = ReplayBuffer(_dataset([5, 5]), history=2, seed=7).sample(32)
    assert torch.equal(a.obs, b.obs) and torch.equal(a.hist_obs, b.hist_obs)


def test_sample_pair_batches_are_independent() -> None:
    """sample_pair returns two differently drawn batches of the requested size."""
    h1, h2 = ReplayBuffer(_dataset([50, 50]), history=2, seed=0).sample_pair(64)
    assert h1.batch_size == h2.batch_size == 64
    assert not torch.equal(h1.obs, h2.obs)


def test_append_episodes_extends_buffer() -> None:
    """Adding episodes makes their transitions sampleable and keeps the old ones."""
    buf = ReplayBuffer(_dataset([4]), history=2, seed=0)
    buf.add([_episode(9, 1000, 6)])
    assert len(buf) == 10 and buf.num_episodes == 2
    eps = set(buf.sample(500).obs[:, 1].int().tolist())
    assert eps == {0, 9}


def test_frame_stacks_repeat_first_frame_at_start() -> None:
    """Stacked frames are o_{t-2}, o_{t-1}, o_t, clamped to the episode's first frame."""
    data = _dataset([4, 4], frames=True)
    buf = ReplayBuffer(data, history=2, seed=0)
    b = buf.sample(200)
    assert b.obs.shape == (200, 9, 84, 84) and b.obs.dtype == torch.uint8
    assert b.hist_obs.shape == (200, 2, 9, 84, 84)
    starts = [int(e.steps[0]) for e in data.episodes]
    for i in range(200):
        ep = int(b.obs[i, 1, 0, 0])
        t = int(b.obs[i, 6, 0, 0])
        expect = [max(t - 2, starts[ep]), max(t - 1, starts[ep]), t]
        assert b.obs[i, [0, 3, 6], 0, 0].tolist() == expect
        assert b.next_obs[i, 6, 0, 0] == t + 1


def test_obs_mean_std_match_dataset() -> None:
    """obs_mean/obs_std are the dataset's state statistics, with a floor for constants."""
    data = _dataset([5, 7])
    buf = ReplayBuffer(data, history=1)
    allobs = np.concatenate([e.obs for e in data.episodes])
    np.testing.assert_allclose(buf.obs_mean, allobs.mean(0), rtol=1e-6)
    np.testing.assert_allclose(buf.obs_std, np.maximum(allobs.std(0), 1e-3), rtol=1e-5)
    const = ReplayBuffer(_dataset([5]), history=1)
    assert const.obs_std[1] == pytest.approx(1e-3)


def test_model_transition_lies_ahead_in_the_same_episode() -> None:
    """With model_horizon m the models' transition u is one of t .. t+m-1 of t's episode."""
    data = _dataset([3, 10, 1, 6])
    buf = ReplayBuffer(data, history=2, seed=0, model_horizon=4)
    b = buf.sample(2000)
    t, u = b.obs[:, 0], b.model_obs[:, 0]
    ahead = (u - t).int()
    assert ahead.min() == 0 and ahead.max() == 3
    assert set(ahead.tolist()) == {0, 1, 2, 3}
    assert torch.equal(b.model_obs[:, 1], b.obs[:, 1])  # same episode
    assert torch.equal(b.model_next_obs[:, 0], u + 1)
    assert torch.equal(b.model_next_obs[:, 1], b.obs[:, 1])  # never past the episode's end
    assert torch.allclose(b.model_action[:, 0], u + 0.25)
    assert torch.allclose(b.model_reward[:, 0], u + 0.5)
    plain = ReplayBuffer(data, history=2, seed=0).sample(8)
    assert plain.model_obs is None and plain.model_transition()[0] is plain.obs
