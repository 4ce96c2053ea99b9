"""The context read-out and novelty monitor: psi in the context's units, and how far from training.

psi lives in its own learned space. An affine map psi -> context, fitted by ridge least squares
on the checkpoint's own estimates over the training contexts (in-process rollouts of the
deployed policy, switching through the task's train preset), turns it into "torso_length:
estimated 1.21 m". It is calibrated once, stored in the checkpoint (`extra['context_readout']`)
and then only applied: never fitted on the run it shows, so it cannot overstate what psi
carries. The rollout's segments are split into calibration and held-back ones; the held-back
RMSE and R^2 are stored with it and say how far to trust it.

Beside it, the novelty monitor (`extra['context_novelty']`): the distance of the live psi
(averaged over the last `window` steps of the episode) from the nearest mean psi of a training
context, in units of the typical within-context spread. Its threshold is the 99th percentile of
that score on the held-back training segments, times a margin: above it, the robot runs in a
context it was not trained on (the estimator warns on /diagnostics).

This module holds what the live nodes need (the monitors, fitting them, reading and writing
them in a checkpoint) and so belongs to the learning core; calibrating them on a rollout of the
policy is offline work: zeus_ros/offline/evaluation/calibrate.py.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import io
import os
from pathlib import Path
from typing import Any

import numpy as np

from zeus_ros.atomic_file import atomic_write

__all__ = [
    'EXTRA_KEY',
    'NOVELTY_KEY',
    'READOUT_STEPS',
    'TRAIN_MEAN_KEY',
    'ContextReadout',
    'NoveltyMonitor',
    'NoveltyTracker',
    'fit_novelty',
    'fit_readout',
    'held_back',
    'monitors_from_extra',
    'readout_from_checkpoint_bytes',
    'store_readout',
    'store_train_mean',
    'stored_monitors',
    'stored_train_mean',
]

EXTRA_KEY = 'context_readout'
NOVELTY_KEY = 'context_novelty'
READOUT_STEPS = 2000
"""Steps of the policy on its train contexts that fit both (`zeus export`, `zeus train`)."""
TRAIN_MEAN_KEY = 'train_mean_context'
"""The agent's mean context over its train values: what a frozen-context run freezes to."""
RIDGE = 1e-3
"""Ridge penalty (relative to the mean psi variance): keeps the map stable when psi is flat."""
NOVELTY_WINDOW = 10
"""Steps of psi averaged before scoring (per-step psi is noisy; within one episode)."""
NOVELTY_QUANTILE = 0.95
NOVELTY_MARGIN = 1.5
"""Threshold = margin x the 95th percentile of the held-back training scores (the steps whose
window lies inside one segment: right after a switch the window mixes two contexts)."""


@dataclass(frozen=True)
class ContextReadout:
    """An affine map psi -> context values, with what it was fitted on and its held-out error."""

    names: tuple[str, ...]
    weights: np.ndarray
    """(context_dim, len(names))"""
    bias: np.ndarray
    """(len(names),)"""
    heldout_rmse: tuple[float, ...]
    heldout_r2: tuple[float, ...]
    fitted_on: str

    def apply(self, psi: np.ndarray) -> np.ndarray:
        """Context values (in the context's units) for one psi or a stack of them."""
        return np.asarray(psi, np.float64) @ self.weights + self.bias

    def to_dict(self) -> dict[str, Any]:
        """Plain data, as checkpoints store `extra`."""
        return {'names': list(self.names), 'weights': self.weights.tolist(),
                'bias': self.bias.tolist(), 'heldout_rmse': list(self.heldout_rmse),
                'heldout_r2': list(self.heldout_r2), 'fitted_on': self.fitted_on}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ContextReadout:
        """Inverse of to_dict; ValueError when a field is missing or shapes disagree."""
        try:
            names = tuple(str(n) for n in data['names'])
            weights = np.asarray(data['weights'], np.float64).reshape(-1, len(names))
            bias = np.asarray(data['bias'], np.float64).reshape(len(names))
            readout = cls(names, weights, bias, tuple(map(float, data['heldout_rmse'])),
                          tuple(map(float, data['heldout_r2'])), str(data['fitted_on']))
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f'context read-out: malformed ({error})') from None
        if not (np.isfinite(weights).all() and np.isfinite(bias).all()):
            raise ValueError('context read-out: non-finite weights')
        return readout

    def describe(self) -> str:
        """One line: what it estimates and how well it did on held-back data."""
        errors = ', '.join(f'{n} RMSE {e:.3g}, R^2 {r:.2f}' for n, e, r in
                           zip(self.names, self.heldout_rmse, self.heldout_r2, strict=True))
        return f'context read-out ({errors} on held-back data; fitted on {self.fitted_on})'


@dataclass(frozen=True)
class NoveltyMonitor:
    """Distance of the recent psi from the training contexts' mean psi, and its threshold."""

    centroids: np.ndarray
    """(number of training context values, context_dim): mean psi per training value."""
    scale: float
    """Median distance of a training step's smoothed psi to its nearest centroid."""
    threshold: float
    window: int
    fitted_on: str

    def score(self, psi_mean: np.ndarray) -> float:
        """Novelty of a (window-averaged) psi: nearest-centroid distance over `scale`."""
        distances = np.linalg.norm(self.centroids - np.asarray(psi_mean, np.float64), axis=1)
        return float(distances.min() / self.scale)

    def to_dict(self) -> dict[str, Any]:
        """Plain data, as checkpoints store `extra`."""
        return {'centroids': self.centroids.tolist(), 'scale': self.scale,
                'threshold': self.threshold, 'window': self.window, 'fitted_on': self.fitted_on}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> NoveltyMonitor:
        """Inverse of to_dict; ValueError when a field is missing or not finite."""
        try:
            monitor = cls(np.atleast_2d(np.asarray(data['centroids'], np.float64)),
                          float(data['scale']), float(data['threshold']), int(data['window']),
                          str(data['fitted_on']))
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f'context novelty monitor: malformed ({error})') from None
        if not (np.isfinite(monitor.centroids).all() and monitor.scale > 0
                and np.isfinite(monitor.threshold) and monitor.window >= 1):
            raise ValueError('context novelty monitor: non-finite or non-positive values')
        return monitor

    def describe(self) -> str:
        """One line: what it compares with and when it warns."""
        return (f'context novelty monitor ({len(self.centroids)} training contexts, warns above '
                f'{self.threshold:.3g} (psi averaged over {self.window} steps); fitted on '
                f'{self.fitted_on})')


class NoveltyTracker:
    """Per-step novelty of a live psi stream: the window restarts with every episode."""

    def __init__(self, monitor: NoveltyMonitor, k: int) -> None:
        self.monitor, self.k = monitor, k
        self._recent: list[np.ndarray] = []

    def update(self, psi: np.ndarray, history_length: int, first: bool) -> float | None:
        """The novelty after this step; None until the episode's history is full (k)."""
        if first:
            self._recent.clear()
        if history_length < self.k:
            return None
        self._recent.append(np.asarray(psi, np.float64))
        del self._recent[:-self.monitor.window]
        return self.monitor.score(np.mean(self._recent, axis=0))


def _smoothed(psi: np.ndarray, episodes: np.ndarray, window: int) -> np.ndarray:
    """Mean of each step's psi with up to window - 1 earlier steps of the same episode."""
    out = np.empty_like(psi)
    for i in range(len(psi)):
        start = i
        while start > 0 and i - start + 1 < window and episodes[start - 1] == episodes[i]:
            start -= 1
        out[i] = psi[start:i + 1].mean(0)
    return out


def held_back(groups: np.ndarray, truth: np.ndarray, every: int = 4) -> np.ndarray:
    """Mask of the held-back steps: every `every`-th segment of each context value.

    Per value, so every value is both fitted and (when it has two segments or more) scored:
    holding back every 4th segment outright would, with 8 values in a fixed cycle, hold back
    the same two values always.
    """
    keys = [tuple(np.round(row, 6)) for row in np.asarray(truth, np.float64)]
    segments: dict[tuple[float, ...], list[Any]] = {}
    for label, key in zip(groups, keys, strict=True):
        if label not in segments.setdefault(key, []):
            segments[key].append(label)
    held_labels = []
    for labels in segments.values():
        if len(labels) >= every:
            held_labels += labels[every - 1::every]
        elif len(labels) >= 2:
            held_labels.append(labels[-1])
    if not held_labels:
        raise ValueError('context read-out: need two segments of one context value to hold '
                         'one back (calibrate on more steps)')
    return np.isin(groups, held_labels)


def fit_novelty(psi: np.ndarray, truth: np.ndarray, groups: np.ndarray, episodes: np.ndarray,
                *, fitted_on: str, window: int = NOVELTY_WINDOW) -> NoveltyMonitor:
    """Centroids per training value from the fitted segments; threshold from held-back ones."""
    psi = np.asarray(psi, np.float64)
    held = held_back(groups, truth)
    keys = np.asarray([hash(tuple(np.round(row, 6))) for row in np.asarray(truth, np.float64)])
    centroids = np.stack([psi[(keys == key) & ~held].mean(0) for key in np.unique(keys[~held])])
    smooth = _smoothed(psi, episodes, window)
    distances = np.linalg.norm(smooth[:, None, :] - centroids[None], axis=2).min(1)
    # Steps whose window lies inside their own segment (after a switch it mixes two contexts).
    settled = np.asarray([i >= window - 1 and groups[i - window + 1] == groups[i]
                          and episodes[i - window + 1] == episodes[i]
                          for i in range(len(groups))])
    scale = float(np.median(distances[~held & settled])) or 1e-9
    threshold = NOVELTY_MARGIN * float(np.quantile(distances[held & settled] / scale,
                                                   NOVELTY_QUANTILE))
    return NoveltyMonitor(centroids, scale, threshold, window, fitted_on)


def _ridge(psi: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean_psi, mean_truth = psi.mean(0), truth.mean(0)
    centered = psi - mean_psi
    scale = float(centered.var(0).mean()) or 1.0
    gram = centered.T @ centered + RIDGE * scale * len(psi) * np.eye(psi.shape[1])
    weights = np.linalg.solve(gram, centered.T @ (truth - mean_truth))
    return weights, mean_truth - mean_psi @ weights


def fit_readout(psi: np.ndarray, truth: np.ndarray, names: Sequence[str], groups: np.ndarray,
                *, fitted_on: str) -> ContextReadout:
    """Fit on the context segments not held back (held_back); score on the held-back ones.

    ValueError when no segment can be held back.
    """
    psi, truth = np.asarray(psi, np.float64), np.asarray(truth, np.float64)
    held = held_back(groups, truth)
    weights, bias = _ridge(psi[~held], truth[~held])
    error = psi[held] @ weights + bias - truth[held]
    rmse = np.sqrt((error ** 2).mean(0))
    # R^2 against the spread of the contexts calibrated on: 0 = no better than their mean.
    spread = truth.var(0)
    r2 = np.where(spread > 0, 1.0 - (error ** 2).mean(0) / np.where(spread > 0, spread, 1.0),
                  np.nan)
    return ContextReadout(tuple(names), weights, bias, tuple(rmse.tolist()),
                          tuple(r2.tolist()), fitted_on)


def monitors_from_extra(extra: Mapping[str, Any], context_dim: int | None = None
                        ) -> tuple[ContextReadout | None, NoveltyMonitor | None]:
    """The read-out and novelty monitor in a loaded checkpoint's `extra` (None: absent).

    `context_dim`: the agent's psi size; ValueError when a monitor expects another.
    """
    stored_readout, stored_novelty = extra.get(EXTRA_KEY), extra.get(NOVELTY_KEY)
    readout = None if stored_readout is None else ContextReadout.from_dict(stored_readout)
    novelty = None if stored_novelty is None else NoveltyMonitor.from_dict(stored_novelty)
    for what, size in (('context read-out', None if readout is None else len(readout.weights)),
                       ('novelty monitor', None if novelty is None
                        else novelty.centroids.shape[1])):
        if context_dim is not None and size is not None and size != context_dim:
            raise ValueError(f'its {what} expects psi of {size} values, the agent has '
                             f'{context_dim}')
    return readout, novelty


def stored_monitors(data: bytes) -> tuple[ContextReadout | None, NoveltyMonitor | None]:
    """The read-out and novelty monitor stored in a checkpoint file's bytes (None: absent)."""
    import torch

    payload = torch.load(io.BytesIO(data), map_location='cpu', weights_only=True)
    return monitors_from_extra(payload.get('extra', {}) if isinstance(payload, dict) else {})


def stored_train_mean(data: bytes) -> np.ndarray | None:
    """The train-mean context stored in a checkpoint file's bytes (None: absent)."""
    import torch

    payload = torch.load(io.BytesIO(data), map_location='cpu', weights_only=True)
    extra = payload.get('extra', {}) if isinstance(payload, dict) else {}
    mean = extra.get(TRAIN_MEAN_KEY)
    return None if mean is None else np.asarray(mean, dtype=np.float64)


def store_train_mean(checkpoint: str | os.PathLike[str], mean: np.ndarray) -> Path:
    """Write the train-mean context into the checkpoint's `extra`, in place, atomically."""
    import torch

    path = Path(checkpoint)
    payload = torch.load(path, map_location='cpu', weights_only=True)
    payload['extra'] = {**payload.get('extra', {}),
                        TRAIN_MEAN_KEY: [float(v) for v in np.asarray(mean).ravel()]}
    _save(payload, path)
    return path


def readout_from_checkpoint_bytes(data: bytes) -> ContextReadout | None:
    """The read-out stored in a checkpoint file's bytes, or None when it has none."""
    return stored_monitors(data)[0]


def store_readout(checkpoint: str | os.PathLike[str], readout: ContextReadout,
                  out: str | os.PathLike[str] | None = None,
                  novelty: NoveltyMonitor | None = None) -> Path:
    """Write `checkpoint` with the read-out (and novelty monitor) in `extra`, atomically.

    To `out` (default: in place); everything else in the file is kept as it is.
    """
    import torch

    source = Path(checkpoint)
    target = Path(out) if out is not None else source
    payload = torch.load(source, map_location='cpu', weights_only=True)
    payload['extra'] = {**payload.get('extra', {}), EXTRA_KEY: readout.to_dict(),
                        **({NOVELTY_KEY: novelty.to_dict()} if novelty is not None else {})}
    _save(payload, target)
    return target


def _save(payload: dict[str, Any], path: Path) -> None:
    """torch.save atomically, through a handle (the archive's inner name is fixed).

    Serialized first, so that a full disk names what the whole file needs.
    """
    import io

    import torch

    buffer = io.BytesIO()
    torch.save(payload, buffer)
    with atomic_write(path, 'wb', size=buffer.getbuffer().nbytes) as handle:
        handle.write(buffer.getbuffer())
