"""The context read-out: psi mapped to the context's physical units, calibrated offline.

psi lives in its own learned space. An affine map psi -> context, fitted by ridge least squares
on the checkpoint's own estimates over the training contexts (in-process rollouts of the
deployed policy, switching through the task's train preset), turns it into "torso_length:
estimated 1.21 m". It is calibrated once, stored in the checkpoint (`extra['context_readout']`)
and then only applied: never fitted on the run it shows, so it cannot overstate what psi
carries. The rollout's segments are split into calibration and held-back ones; the held-back
RMSE and R^2 are stored with it and say how far to trust it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import io
import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ['EXTRA_KEY', 'ContextReadout', 'calibrate_readout', 'fit_readout',
           'readout_from_checkpoint_bytes', 'store_readout']

EXTRA_KEY = 'context_readout'
RIDGE = 1e-3
"""Ridge penalty (relative to the mean psi variance): keeps the map stable when psi is flat."""


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


def _ridge(psi: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean_psi, mean_truth = psi.mean(0), truth.mean(0)
    centered = psi - mean_psi
    scale = float(centered.var(0).mean()) or 1.0
    gram = centered.T @ centered + RIDGE * scale * len(psi) * np.eye(psi.shape[1])
    weights = np.linalg.solve(gram, centered.T @ (truth - mean_truth))
    return weights, mean_truth - mean_psi @ weights


def fit_readout(psi: np.ndarray, truth: np.ndarray, names: Sequence[str], groups: np.ndarray,
                *, fitted_on: str, holdout_every: int = 4) -> ContextReadout:
    """Fit on the groups (context segments) not held back; score on every `holdout_every`-th.

    ValueError when there are too few groups to hold any back.
    """
    psi, truth = np.asarray(psi, np.float64), np.asarray(truth, np.float64)
    labels = np.unique(groups)
    if len(labels) < 2:
        raise ValueError('context read-out: need at least 2 context segments to hold one back')
    held_labels = labels[holdout_every - 1::holdout_every] if len(labels) >= holdout_every \
        else labels[-1:]
    held = np.isin(groups, held_labels)
    weights, bias = _ridge(psi[~held], truth[~held])
    error = psi[held] @ weights + bias - truth[held]
    rmse = np.sqrt((error ** 2).mean(0))
    # R^2 against the spread of the contexts calibrated on: 0 = no better than their mean.
    spread = truth.var(0)
    r2 = np.where(spread > 0, 1.0 - (error ** 2).mean(0) / np.where(spread > 0, spread, 1.0),
                  np.nan)
    return ContextReadout(tuple(names), weights, bias, tuple(rmse.tolist()),
                          tuple(r2.tolist()), fitted_on)


def calibrate_readout(agent: Any, *, steps: int = 2000, every: int | None = None,
                      seed: int = 1000, progress: bool = False) -> ContextReadout:
    """Roll the agent out through its task's train contexts (switching, mid-episode) and fit.

    `agent` is an InferenceAgent with a learned context. Only steps with a full history count
    (what the estimator publishes once an episode is k steps old).
    """
    from zeus_ros.offline.collect import AgentPolicy
    from zeus_ros.offline.evaluate import (
        _make_env,
        _switch_schedule,
        default_switch_every,
        run_steps,
        split_values,
        switching_order,
    )

    values = switching_order(split_values(agent.task, 'train'), seed)
    every = every or max(agent.k * 4, default_switch_every(agent.task))
    env, task = _make_env(agent.task, _switch_schedule(values, every), seed)
    try:
        trace = run_steps(env, task, AgentPolicy(agent, noise=0.0, seed=seed), steps,
                          desc='read-out', progress=progress)
    finally:
        task.close()
    if trace.psi is None or trace.psi.shape[1] == 0:
        raise ValueError(f'context read-out: a {agent.method} checkpoint has no learned context')
    full = trace.history_length >= agent.k
    return fit_readout(trace.psi[full], trace.context[full], agent.context_names,
                       trace.segment[full],
                       fitted_on=f'{int(full.sum())} steps of the policy on the train contexts '
                       f'of {agent.task}, switching every {every} steps, seed {seed}')


def readout_from_checkpoint_bytes(data: bytes) -> ContextReadout | None:
    """The read-out stored in a checkpoint file's bytes, or None when it has none."""
    import torch

    payload = torch.load(io.BytesIO(data), map_location='cpu', weights_only=True)
    stored = payload.get('extra', {}).get(EXTRA_KEY) if isinstance(payload, dict) else None
    return None if stored is None else ContextReadout.from_dict(stored)


def store_readout(checkpoint: str | os.PathLike[str], readout: ContextReadout,
                  out: str | os.PathLike[str] | None = None) -> Path:
    """Write `checkpoint` with the read-out in its `extra` to `out` (default: in place), atomic.

    Everything else in the file is kept as it is (weights, config, provenance).
    """
    import torch

    source = Path(checkpoint)
    target = Path(out) if out is not None else source
    payload = torch.load(source, map_location='cpu', weights_only=True)
    payload['extra'] = {**payload.get('extra', {}), EXTRA_KEY: readout.to_dict()}
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f'.{target.name}.tmp{os.getpid()}')
    torch.save(payload, tmp)
    tmp.replace(target)
    return target
