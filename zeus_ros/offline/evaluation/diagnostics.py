"""Adaptation diagnostics: does the policy use its context, and does using it pay.

Computed by `zeus eval` from the constant-context episodes of a split (evaluate.Trace), for every
method alike ('context' below is psi(H), or the true context for the oracles):
  - context sensitivity: mean |delta action| (actions scaled to [-1, 1]) of the deterministic
    actor on the same observations when the live context is replaced by the mean context of the
    split's other extreme value (both directions, averaged);
  - spread / noise: RMS distance of the per-value mean contexts from their grand mean, over the
    RMS deviation of the context from its value's mean within the episodes. Below ~1 the
    context cannot tell the values apart, whatever its absolute size;
  - value of adaptation: return with the context live minus return with it frozen (to the mean
    context of the extreme value farthest from each value, to the mean over all values, and
    to the mean over the *train* values), on the same environment seeds, so every difference
    is paired. Off the train values the last one is the question a deployed robot meets: is
    acting on the inferred context better than acting as in training? (The split's own mean
    is itself an unseen context there; docs/results.md, session 8.) 'steady' freezes at the
    train values' mean only after the first k steps of each episode, so that what psi says
    while its history fills (the start of an episode, alike in every context) is not counted
    as adaptation.
The headroom over seeds (oracle - no_context, and the share of it a method recovers) is in
report.py, which sees every method of a task.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.rollout import Trace

__all__ = ['DIAGNOSTICS', 'context_sensitivity', 'extreme_indices', 'farthest_extreme',
           'frozen_contexts', 'mean_contexts', 'policy_contexts', 'spread_over_noise']

DIAGNOSTICS = ('sensitivity', 'spread_noise', 'adaptation_value_other', 'adaptation_value_mean',
               'adaptation_value_train_mean', 'adaptation_value_steady')
"""Diagnostic columns of an eval summary (NaN where the method has no context)."""


def policy_contexts(trace: Trace, agent: InferenceAgent) -> np.ndarray | None:
    """(T, C) the context each action of `trace` was computed from; None without a context.

    Only steps with a full history count for psi methods (the first k steps of an episode are
    start-up); the true context is complete from the first step.
    """
    if agent.context_dim == 0:
        return None
    if agent.needs_true_context:
        return np.asarray(trace.context, np.float32)
    if trace.psi is None:
        return None
    return np.asarray(trace.psi[trace.history_length >= agent.k], np.float32)


def _steps(trace: Trace, agent: InferenceAgent) -> np.ndarray:
    """Observations matching policy_contexts(trace, agent)."""
    if agent.needs_true_context:
        return trace.obs
    return trace.obs[trace.history_length >= agent.k]


def extreme_indices(values: Sequence[dict[str, float]]) -> tuple[int, int]:
    """Indices of the smallest and largest value (by the first context parameter)."""
    first = [next(iter(v.values())) for v in values]
    return int(np.argmin(first)), int(np.argmax(first))


def farthest_extreme(values: Sequence[dict[str, float]], index: int) -> int:
    """Of the two extreme values, the one farther from values[index]."""
    lo, hi = extreme_indices(values)
    first = [next(iter(v.values())) for v in values]
    return lo if abs(first[index] - first[lo]) >= abs(first[index] - first[hi]) else hi


def context_sensitivity(agent: InferenceAgent, traces: Sequence[Trace],
                        values: Sequence[dict[str, float]]) -> float:
    """Mean |delta action| in [-1, 1] units when the context of one extreme replaces the other's.

    NaN without a context or with fewer than two distinct values, and for a pixel agent: a
    trace keeps the state of each step, not the frames such an agent acts on.
    """
    lo, hi = extreme_indices(values)
    if lo == hi or agent.context_dim == 0 or agent.obs_kind != 'state':
        return float('nan')
    half_range = (agent.action_high - agent.action_low) / 2
    deltas = []
    for own, other in ((lo, hi), (hi, lo)):
        live = policy_contexts(traces[own], agent)
        swapped = policy_contexts(traces[other], agent)
        if live is None or swapped is None or not len(live) or not len(swapped):
            return float('nan')
        obs = _steps(traces[own], agent)
        replaced = np.repeat(swapped.mean(0, keepdims=True), len(obs), axis=0)
        delta = agent.act(obs, live) - agent.act(obs, replaced)
        deltas.append(float(np.mean(np.abs(delta) / half_range)))
    return float(np.mean(deltas))


def spread_over_noise(contexts: Sequence[np.ndarray | None]) -> tuple[float, float, float]:
    """(spread, noise, spread / noise) of per-value context samples; NaNs without contexts."""
    if any(c is None or not len(c) for c in contexts) or len(contexts) < 2:
        return float('nan'), float('nan'), float('nan')
    means = np.stack([c.mean(0) for c in contexts])
    spread = float(np.sqrt(np.mean(np.sum((means - means.mean(0)) ** 2, axis=1))))
    within = np.concatenate([np.sum((c - c.mean(0)) ** 2, axis=1) for c in contexts])
    noise = float(np.sqrt(np.mean(within)))
    # a constant per value (the true context; float32 rounding of small values such as goal
    # coordinates leaves ~1e-6 of the spread)
    if noise <= 1e-4 * max(spread, 1e-30):
        return spread, noise, float('inf')
    ratio = spread / noise
    return spread, noise, ratio


def mean_contexts(agent: InferenceAgent, traces: Sequence[Trace]) -> list[np.ndarray] | None:
    """The mean context of each trace (one per value); None without a context."""
    contexts = [policy_contexts(t, agent) for t in traces]
    if any(c is None or not len(c) for c in contexts):
        return None
    return [c.mean(0) for c in contexts]


def frozen_contexts(agent: InferenceAgent, traces: Sequence[Trace],
                    values: Sequence[dict[str, float]],
                    train_mean: np.ndarray | None = None) -> dict[str, list[Any]] | None:
    """Per value, the context to freeze: 'other', 'mean' and, when given, 'train_mean'.

    'other': the mean context of the farthest extreme value; 'mean': over the split's values;
    'train_mean': over the train values (computed by the caller).
    """
    means = mean_contexts(agent, traces)
    if means is None:
        return None
    overall = np.mean(means, axis=0)
    frozen = {'other': [means[farthest_extreme(values, i)] for i in range(len(values))],
              'mean': [overall for _ in values]}
    if train_mean is not None:
        frozen['train_mean'] = [np.asarray(train_mean) for _ in values]
    return frozen
