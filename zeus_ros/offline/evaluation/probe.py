"""Identifiability probe (paper appendix B.2): is the context inferable from k transitions.

A two-layer MLP regresses the true context from the last k = 5 (observation, action) tuples of
random-policy data. Its held-out MSE, next to the MSE of predicting the training mean, says
whether k steps carry the context at all: if the probe cannot beat the mean, no psi can.
Windows never span an episode start or a context switch. Held-out windows come in contiguous
blocks, so a test window never shares 4 of its 5 tuples with a training window.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

__all__ = ['ProbeResult', 'Rollout', 'probe_context', 'windows']

_BLOCK = 50
"""Consecutive windows per train/test block (leak guard)."""


@dataclass(frozen=True)
class Rollout:
    """Random-policy steps: o_t, the action taken at o_t, the true context and its segment."""

    obs: np.ndarray
    """(N, D) state observations."""
    action: np.ndarray
    """(N, A) action chosen at each observation."""
    context: np.ndarray
    """(N, C) true context in force at each observation."""
    first: np.ndarray
    """(N,) bool: episode starts."""
    segment: np.ndarray
    """(N,) int: context segment counter (changes at every switch)."""


@dataclass(frozen=True)
class ProbeResult:
    """Held-out regression quality of the probe."""

    mse: float
    """Held-out MSE of the probe, in context units squared."""
    baseline_mse: float
    """Held-out MSE of predicting the training mean context."""
    train_mse: float
    """Final MSE on the training windows."""
    num_train: int
    num_test: int

    @property
    def r2(self) -> float:
        """1 - mse / baseline_mse: 1 is perfect, 0 is no better than the mean."""
        return 1.0 - self.mse / max(self.baseline_mse, 1e-12)


def _network(in_dim: int, hidden: int, out_dim: int, dropout: float) -> torch.nn.Module:
    """Two hidden ReLU layers; dropout, because random-policy windows are few and alike."""
    nn = torch.nn
    return nn.Sequential(nn.Linear(in_dim, hidden), nn.ReLU(), nn.Dropout(dropout),
                         nn.Linear(hidden, hidden), nn.ReLU(), nn.Dropout(dropout),
                         nn.Linear(hidden, out_dim))


def windows(rollout: Rollout, k: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Flattened k-tuple windows (o, a) ending at each step, and the context at that step.

    A window is kept only when its k steps share one episode and one context segment.
    """
    n = rollout.obs.shape[0]
    episode = np.cumsum(rollout.first.astype(np.int64))  # equal ends <=> no reset between
    ends = np.arange(k - 1, n)
    starts = ends - (k - 1)
    same = (episode[starts] == episode[ends]) & (rollout.segment[starts] == rollout.segment[ends])
    ends = ends[same]
    index = ends[:, None] + np.arange(-(k - 1), 1)
    tuples = np.concatenate([rollout.obs[index], rollout.action[index]], axis=-1)
    return tuples.reshape(len(ends), -1).astype(np.float32), \
        rollout.context[ends].astype(np.float32)


def _split(n: int, test_fraction: float, rng: np.random.Generator) -> tuple[np.ndarray,
                                                                            np.ndarray]:
    blocks = np.arange(n) // _BLOCK
    num_blocks = int(blocks[-1]) + 1
    num_test = max(1, round(test_fraction * num_blocks))
    if num_blocks < 2:
        raise ValueError(f'the probe needs at least {2 * _BLOCK} windows, got {n}: '
                         'collect more random-policy steps')
    test_blocks = rng.choice(num_blocks, size=num_test, replace=False)
    test = np.isin(blocks, test_blocks)
    return np.flatnonzero(~test), np.flatnonzero(test)


def probe_context(rollouts: Sequence[Rollout], *, k: int = 5, hidden: int = 256,
                  updates: int = 1500, batch_size: int = 256, lr: float = 1e-3,
                  dropout: float = 0.2,
                  test_fraction: float = 0.2, seed: int = 0,
                  progress: bool = True) -> ProbeResult:
    """Train the probe on random-policy windows and report its held-out MSE."""
    parts = [windows(r, k) for r in rollouts]
    x = np.concatenate([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    rng = np.random.default_rng(seed)
    train_idx, test_idx = _split(len(x), test_fraction, rng)
    x_mean, x_std = x[train_idx].mean(0), x[train_idx].std(0) + 1e-6
    y_mean, y_std = y[train_idx].mean(0), y[train_idx].std(0) + 1e-6
    xn = torch.from_numpy((x - x_mean) / x_std)
    yn = torch.from_numpy((y - y_mean) / y_std)
    torch.manual_seed(seed)
    net = _network(x.shape[1], hidden, y.shape[1], dropout)
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    train_t = torch.from_numpy(train_idx)
    for _ in tqdm(range(updates), desc='probe', unit='upd', disable=not progress):
        pick = train_t[torch.randint(len(train_t), (batch_size,))]
        loss = torch.nn.functional.mse_loss(net(xn[pick]), yn[pick])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    scale = torch.from_numpy(y_std)
    net.eval()
    with torch.no_grad():
        pred = net(xn) * scale + torch.from_numpy(y_mean)
    truth = torch.from_numpy(y)

    def mse(idx: np.ndarray, guess: torch.Tensor) -> float:
        return float(((guess[idx] - truth[idx]) ** 2).mean())

    mean_guess = torch.from_numpy(np.broadcast_to(y_mean, y.shape).copy())
    return ProbeResult(mse=mse(test_idx, pred), baseline_mse=mse(test_idx, mean_guess),
                       train_mse=mse(train_idx, pred), num_train=len(train_idx),
                       num_test=len(test_idx))
