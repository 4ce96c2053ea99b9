"""Teacher-labelled rendered episodes for `zeus distill`: collection (DAgger rounds) and batches.

Every visited step stores its rendered frame, the applied action and reward (what psi's history
holds) and the teacher's labels: its deterministic action and its context psi, computed from the
*state* and the teacher's own state history of the same trajectory (the privileged view). Who
acts is the round's choice: the teacher with a little noise (round 0), or the student (DAgger,
Ross et al. 2011: the student is trained on the states its own policy visits, labelled by the
expert). ROS-free; the in-process simulator renders 84x84 frames as sim_bridge publishes them.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
import itertools
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from zeus_ros.atomic_file import atomic_write

__all__ = ['Episode', 'EpisodeStore', 'WindowBatch', 'collect_round', 'save_episodes']


@dataclass
class Episode:
    """One episode's observations, index i = the i-th observation (0: first)."""

    frames: np.ndarray
    """(N, 3, 84, 84) uint8 rendered frames."""
    applied: np.ndarray
    """(N, A) float32: the action that led to observation i (zeros at i = 0)."""
    reward: np.ndarray
    """(N,) float32: the reward that came with observation i (0 at i = 0)."""
    teacher_action: np.ndarray
    """(N, A) float32: the teacher's deterministic action at observation i, in task bounds."""
    teacher_psi: np.ndarray
    """(N, C) float32: the teacher's context at observation i (C = 0 without one)."""
    context: np.ndarray
    """(N, P) float64: the true context (for diagnostics only)."""
    state: np.ndarray
    """(N, S) float32: the simulator state the teacher saw (S = 0 in data saved before it was
    stored); the target of a teacher-head student's phi."""

    def __len__(self) -> int:
        return len(self.frames)


@dataclass
class WindowBatch:
    """E windows of consecutive observations, each with the k observations before it."""

    stacks: torch.Tensor
    """(E, k + L, 9, 84, 84) uint8 frame stacks (3 frames, repeated at the episode start)."""
    valid: torch.Tensor
    """(E, k + L) bool: False for positions before the episode's first observation."""
    applied: torch.Tensor
    """(E, k + L, A) float32 applied actions (task bounds)."""
    reward: torch.Tensor
    """(E, k + L) float32."""
    teacher_action: torch.Tensor
    """(E, L, A) float32 labels of the last L positions (task bounds)."""
    teacher_psi: torch.Tensor
    """(E, L, C) float32 labels of the last L positions."""
    state: torch.Tensor
    """(E, k + L, S) float32 states (S = 0 when the data has none)."""


class EpisodeStore:
    """Episodes in memory, bounded by `max_steps` observations (the oldest episodes go first)."""

    def __init__(self, max_steps: int) -> None:
        self.max_steps = int(max_steps)
        self.episodes: deque[Episode] = deque()
        self.steps = 0

    def add(self, episode: Episode) -> None:
        """Keep `episode`; drop the oldest while over the bound."""
        self.episodes.append(episode)
        self.steps += len(episode)
        while self.steps > self.max_steps and len(self.episodes) > 1:
            self.steps -= len(self.episodes.popleft())

    def psi_scale(self) -> np.ndarray:
        """Per-dimension std of the teacher's psi (floored): the units of the psi loss."""
        psi = np.concatenate([e.teacher_psi for e in self.episodes])
        return np.maximum(psi.std(axis=0), 1e-3).astype(np.float32)

    def sample(self, rng: np.random.Generator, episodes: int, window: int, k: int
               ) -> WindowBatch:
        """`episodes` random windows of `window` observations with their k predecessors."""
        pool = [e for e in self.episodes if len(e) >= window]
        if not pool:
            raise ValueError(f'no stored episode holds {window} observations')
        chosen = [pool[i] for i in rng.integers(len(pool), size=episodes)]
        parts: dict[str, list[np.ndarray]] = {name: [] for name in (
            'stacks', 'valid', 'applied', 'reward', 'teacher_action', 'teacher_psi', 'state')}
        for ep in chosen:
            start = int(rng.integers(len(ep) - window + 1))
            idx = np.arange(start - k, start + window)
            valid = idx >= 0
            safe = np.maximum(idx, 0)
            frame_idx = np.maximum(safe[:, None] + np.array([-2, -1, 0])[None], 0)
            stacks = ep.frames[frame_idx]  # (k + L, 3 frames, 3, 84, 84)
            parts['stacks'].append(stacks.reshape(len(idx), 9, *ep.frames.shape[2:]))
            parts['valid'].append(valid)
            parts['applied'].append(ep.applied[safe])
            parts['reward'].append(ep.reward[safe])
            parts['teacher_action'].append(ep.teacher_action[start:start + window])
            parts['teacher_psi'].append(ep.teacher_psi[start:start + window])
            parts['state'].append(ep.state[safe])
        return WindowBatch(**{name: torch.from_numpy(np.stack(arrays))
                              for name, arrays in parts.items()})

    def save(self, path: Path) -> None:
        """All episodes in one .npz (the round-0 data, shared by the seeds of a comparison)."""
        save_episodes(path, list(self.episodes))

    def load(self, path: Path) -> None:
        """Add the episodes saved by `save`."""
        with np.load(path) as data:
            bounds = np.cumsum([0, *data['lengths']])
            arrays = {name: data[name] for name in Episode.__dataclass_fields__
                      if name in data.files}
        arrays.setdefault('state', np.zeros((int(bounds[-1]), 0), np.float32))
        for a, b in itertools.pairwise(bounds):
            self.add(Episode(**{name: value[a:b] for name, value in arrays.items()}))


def save_episodes(path: Path, episodes: list[Episode]) -> None:
    """`episodes` in one .npz that `EpisodeStore.load` reads, written atomically."""
    with atomic_write(path, 'wb') as handle:
        np.savez(handle, lengths=np.array([len(e) for e in episodes]),
                 **{name: np.concatenate([getattr(e, name) for e in episodes])
                    for name in Episode.__dataclass_fields__})


def collect_round(task_name: str, schedule: dict[str, Any], teacher: Any, student: Any | None,
                  steps: int, *, seed: int, noise: float, progress: bool = True
                  ) -> tuple[list[Episode], list[float]]:
    """Run `steps` rendered steps; the student acts when given (else the teacher plus noise).

    The teacher labels every visited step from the state (AgentPolicy keeps its state history
    of this very trajectory). Returns the complete episodes and their returns.
    """
    from zeus_ros.offline.evaluation.evaluate import make_env
    from zeus_ros.offline.rollout import AgentPolicy
    from zeus_ros.offline.rollout import record_step as _record

    env, task = make_env(task_name, schedule, seed)
    labeller = AgentPolicy(teacher, noise=0.0, seed=seed)
    actor = None if student is None else AgentPolicy(student, noise=noise, seed=seed + 1)
    rng = np.random.default_rng(seed)
    low, high = (np.asarray(b, np.float32) for b in task.action_bounds)
    cols: dict[str, list[Any]] = {}
    episodes: list[Episode] = []
    returns: list[float] = []
    try:
        es = env.reset()
        for _ in tqdm(range(steps), desc='render', unit='step', disable=not progress,
                      leave=False):
            obs = es.observation
            if obs.first:
                cols = {name: [] for name in Episode.__dataclass_fields__}
            rec = _record(es, task, pixels=True)
            label = labeller(es, rec)
            applied = es.applied_action
            cols['frames'].append(rec.frame.transpose(2, 0, 1))
            cols['applied'].append(np.zeros_like(low) if obs.first or applied is None
                                   else np.asarray(applied, np.float32))
            cols['reward'].append(0.0 if obs.first else float(obs.reward))
            cols['teacher_action'].append(label.action)
            cols['teacher_psi'].append(np.zeros(0, np.float32) if label.context is None
                                       else label.context)
            cols['context'].append(rec.context_values)
            cols['state'].append(np.asarray(rec.state, np.float32))
            if actor is not None:
                action = actor(es, rec).action
            else:
                action = label.action + noise * (high - low) / 2 * rng.standard_normal(len(low))
                action = np.clip(action, low, high).astype(np.float32)
            if obs.last:
                episodes.append(Episode(**{n: np.asarray(v, _DTYPES[n]) for n, v in cols.items()}))
                returns.append(float(np.sum(cols['reward'])))
            es = env.step(action)
    finally:
        task.close()
    return episodes, returns


_DTYPES = {'frames': np.uint8, 'applied': np.float32, 'reward': np.float32,
           'teacher_action': np.float32, 'teacher_psi': np.float32, 'context': np.float64,
           'state': np.float32}
