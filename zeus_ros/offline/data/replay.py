"""Replay buffer over ingested episodes that samples transitions with their k-step history.

Storage is flat: the observations of each episode occupy one contiguous block, each stored
once; a transition index t points at o_t and is valid when o_{t+1} is in the same block.
Histories and frame stacks are built at sample time by index arithmetic, clamped to the
episode's first observation, so nothing ever crosses an episode boundary.

Termination: the tasks here end only by time limit, and StepFeedback has no terminal flag, so
every sampled transition has not_done = 1: the critic bootstraps through episode ends (the
time limit is not part of the state, so treating it as terminal would be wrong).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from zeus_ros.learning.batch import HistoryBatch

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

    from zeus_ros.offline.data.ingest import Dataset, Episode

__all__ = ['FRAME_STACK', 'ReplayBuffer']

FRAME_STACK = 3
"""Frames per pixel observation (the paper's and SAC-AE's stack)."""
_STD_FLOOR = 1e-3


class _Column:
    """A growable numpy array (amortised doubling) so appends do not copy everything."""

    def __init__(self, row_shape: tuple[int, ...], dtype: np.dtype | type) -> None:
        self.data = np.zeros((0, *row_shape), dtype)
        self.size = 0

    def extend(self, rows: np.ndarray) -> None:
        need = self.size + rows.shape[0]
        if need > self.data.shape[0]:
            grown = np.zeros((max(need, 2 * self.data.shape[0]), *self.data.shape[1:]),
                             self.data.dtype)
            grown[: self.size] = self.data[: self.size]
            self.data = grown
        self.data[self.size: need] = rows
        self.size = need

    @property
    def view(self) -> np.ndarray:
        return self.data[: self.size]


class ReplayBuffer:
    """Samples `HistoryBatch`es of k-step histories from a Dataset (seeded, appendable).

    Args:
        dataset: the ingested episodes (more can be added with `add`).
        history: k, the number of past transitions in each history.
        pixels: sample stacked frames as observations; default: when the dataset has frames.
        device: where the sampled tensors go.
        seed: seed of the sampling generator.
        model_horizon: > 1: each batch also carries a transition u drawn uniformly from
            t .. t + model_horizon - 1 of the same episode (clamped to its last transition),
            the one the context-conditioned models predict (ZeusConfig.model_horizon).
        anchor: each episode's behaviour-cloning weight (batches then carry `anchor`): a
            continual round anchors rehearsal strongly and new contexts weakly.
    """

    def __init__(
        self,
        dataset: Dataset,
        *,
        history: int,
        pixels: bool | None = None,
        device: torch.device | str = 'cpu',
        seed: int = 0,
        model_horizon: int = 1,
        anchor: Callable[[Episode], float] | None = None,
    ) -> None:
        if history < 1:
            raise ValueError(f'history (k) must be >= 1, got {history}')
        if model_horizon < 1:
            raise ValueError(f'model_horizon must be >= 1, got {model_horizon}')
        self.history = int(history)
        self.model_horizon = int(model_horizon)
        self.pixels = dataset.has_frames if pixels is None else bool(pixels)
        if self.pixels and not dataset.has_frames:
            raise ValueError('pixels=True but the dataset has no frames '
                             '(collect with --pixels / record /zeus/observation/image)')
        self.device = torch.device(device)
        self.task = dataset.task
        self.context_names = dataset.context_names
        self._rng = np.random.default_rng(seed)
        ep0 = dataset.episodes[0]
        self._state = _Column(ep0.obs.shape[1:], np.float32)
        self._frames = _Column(ep0.frames.shape[1:], np.uint8) if self.pixels else None
        self._action = _Column(ep0.action.shape[1:], np.float32)
        self._reward = _Column((), np.float32)
        self._context = _Column(ep0.context.shape[1:], np.float32)
        self._ep_start = _Column((), np.int64)
        self._ep_last = _Column((), np.int64)  # the episode's last valid transition index
        self._valid = _Column((), np.int64)
        self._anchor_of = anchor
        self._anchor = _Column((), np.float32) if anchor is not None else None
        self._sum = np.zeros(ep0.obs.shape[1], np.float64)
        self._sumsq = np.zeros(ep0.obs.shape[1], np.float64)
        self.num_episodes = 0
        self.add(dataset.episodes)

    def add(self, episodes: Iterable[Episode]) -> None:
        """Append episodes (e.g. from a newly ingested bag)."""
        for ep in episodes:
            n = ep.obs.shape[0]
            if n < 2:
                continue
            if ep.obs.shape[1:] != self._state.data.shape[1:]:
                raise ValueError(f'{ep.source}: episode {ep.episode} has obs shape '
                                 f'{ep.obs.shape[1:]}, buffer holds {self._state.data.shape[1:]}')
            if ep.action.shape[1:] != self._action.data.shape[1:]:
                raise ValueError(f'{ep.source}: episode {ep.episode} has action shape '
                                 f'{ep.action.shape[1:]}, buffer holds '
                                 f'{self._action.data.shape[1:]}')
            if self._frames is not None:
                if ep.frames is None:
                    raise ValueError(f'{ep.source}: episode {ep.episode} has no frames')
                self._frames.extend(ep.frames)
            start = self._state.size
            self._state.extend(ep.obs.astype(np.float32))
            # row i holds a_i and r_{i+1}; the episode's last row is padding (never valid).
            self._action.extend(np.concatenate([ep.action, np.zeros_like(ep.action[:1])]))
            self._reward.extend(np.append(ep.reward, 0.0).astype(np.float32))
            self._context.extend(ep.context.astype(np.float32))
            self._ep_start.extend(np.full(n, start, np.int64))
            self._ep_last.extend(np.full(n, start + n - 2, np.int64))
            self._valid.extend(np.arange(start, start + n - 1, dtype=np.int64))
            if self._anchor is not None and self._anchor_of is not None:
                self._anchor.extend(np.full(n, self._anchor_of(ep), np.float32))
            self._sum += ep.obs.sum(0)
            self._sumsq += np.square(ep.obs).sum(0)
            self.num_episodes += 1

    def __len__(self) -> int:
        """Number of transitions that can be sampled."""
        return self._valid.size

    @property
    def obs_mean(self) -> np.ndarray:
        """Per-dimension mean of all stored state observations (float32)."""
        return (self._sum / max(self._state.size, 1)).astype(np.float32)

    @property
    def obs_std(self) -> np.ndarray:
        """Per-dimension std of the state observations, floored at 1e-3 (constant features)."""
        count = max(self._state.size, 1)
        var = np.maximum(self._sumsq / count - np.square(self._sum / count), 0.0)
        return np.maximum(np.sqrt(var), _STD_FLOOR).astype(np.float32)

    def _obs(self, idx: np.ndarray) -> np.ndarray:
        """Observations at global indices `idx` (any shape): states or stacked frames."""
        if self._frames is None:
            return self._state.view[idx]
        start = self._ep_start.view[idx]
        offsets = np.arange(-(FRAME_STACK - 1), 1)
        stack = np.maximum(idx[..., None] + offsets, start[..., None])
        frames = self._frames.view[stack]  # (..., 3, C, H, W)
        return frames.reshape(*idx.shape, -1, *frames.shape[-2:])

    def sample(self, batch_size: int) -> HistoryBatch:
        """Uniformly sample `batch_size` transitions with their histories."""
        if len(self) == 0:
            raise ValueError('the replay buffer holds no transitions')
        t = self._valid.view[self._rng.integers(0, len(self), batch_size)]
        return self._batch(t)

    def sample_pair(self, batch_size: int) -> tuple[HistoryBatch, HistoryBatch]:
        """Two independent batches (H1, H2 of the context loss)."""
        return self.sample(batch_size), self.sample(batch_size)

    def _batch(self, t: np.ndarray) -> HistoryBatch:
        """Assemble the batch for transition indices `t`."""
        k = self.history
        j = t[:, None] + np.arange(-k, 0)  # (B, k) oldest first
        start = self._ep_start.view[t][:, None]
        mask = j >= start
        jc = np.where(mask, j, start)  # any in-episode index; zeroed below
        hist_obs = self._obs(jc)
        hist_next = self._obs(jc + 1)
        hist_act = self._action.view[jc]
        hist_rew = self._reward.view[jc][..., None]
        for arr in (hist_obs, hist_next, hist_act, hist_rew):
            arr[~mask] = 0
        model: dict[str, torch.Tensor] = {}
        if self.model_horizon > 1:
            ahead = self._rng.integers(0, self.model_horizon, t.shape[0])
            u = np.minimum(t + ahead, self._ep_last.view[t])
            model = {'model_obs': self._tensor(self._obs(u)),
                     'model_action': self._tensor(self._action.view[u]),
                     'model_reward': self._tensor(self._reward.view[u][:, None]),
                     'model_next_obs': self._tensor(self._obs(u + 1))}
        return HistoryBatch(
            obs=self._tensor(self._obs(t)),
            action=self._tensor(self._action.view[t]),
            reward=self._tensor(self._reward.view[t][:, None]),
            next_obs=self._tensor(self._obs(t + 1)),
            not_done=torch.ones((t.shape[0], 1), dtype=torch.float32, device=self.device),
            hist_obs=self._tensor(hist_obs),
            hist_action=self._tensor(hist_act),
            hist_reward=self._tensor(hist_rew),
            hist_next_obs=self._tensor(hist_next),
            hist_mask=self._tensor(mask),
            context=self._tensor(self._context.view[t + 1]),
            anchor=(None if self._anchor is None
                    else self._tensor(self._anchor.view[t][:, None])),
            **model,
        )

    def _tensor(self, arr: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(arr)).to(self.device)
