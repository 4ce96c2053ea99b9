"""Which contexts a recording saw: its context truth, else the deployed checkpoint's read-out.

The gate compares candidate and deployed checkpoint where the robot runs now. A simulator's
recording carries the true context of every step; a robot's carries none. There the deployed
checkpoint's own estimate stands in: psi over each recorded history (the windows the live
estimator saw, from the same checkpoint), mapped to context values by the read-out stored in
the checkpoint (`zeus export --readout-steps`), averaged per recorded segment (per-step psi is
noisy; a segment holds one context) and clipped to the family's declared range. With neither,
the gate falls back to the train values and the history says so.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ['READOUT_MAX_STEPS', 'SeenContexts', 'readout_contexts', 'seen_contexts',
           'spread_rows', 'truth_contexts']

READOUT_MAX_STEPS = 3000
"""At most this many recorded steps are run through psi (evenly strided): enough for a few
steps per segment, bounded however long the round's new data."""


@dataclass
class SeenContexts:
    """The contexts the gate evaluates as 'seen', and where they came from."""

    values: list[dict[str, float]] = field(default_factory=list)
    source: str = 'none'
    """'truth' (the recording's context truth), 'read-out' (the deployed checkpoint's
    estimate), or 'none' (the train values stand in)."""
    detail: str = ''
    """Why the read-out was or was not used: one line for the history and the log."""


def spread_rows(rows: np.ndarray, names: Sequence[str], max_values: int
                ) -> list[dict[str, float]]:
    """Distinct rows (rounded to 1e-3), at most `max_values`, spread evenly over their order."""
    rows = rows[np.isfinite(rows).all(axis=1)]
    if not len(rows):
        return []
    unique = np.unique(np.round(rows, 3), axis=0)
    if len(unique) > max_values:
        unique = unique[np.round(np.linspace(0, len(unique) - 1, max_values)).astype(int)]
    return [{name: float(v) for name, v in zip(names, row, strict=True)} for row in unique]


def truth_contexts(dataset: Any, max_values: int) -> list[dict[str, float]]:
    """Distinct true contexts in `dataset`, at most `max_values`, spread."""
    if not dataset.episodes or not dataset.context_names:
        return []
    rows = np.concatenate([ep.context for ep in dataset.episodes])
    return spread_rows(rows, dataset.context_names, max_values)


def readout_contexts(deployed: Path | str, dataset: Any, max_values: int,
                     max_steps: int = READOUT_MAX_STEPS) -> SeenContexts:
    """The deployed checkpoint's read-out of the recorded histories, one value per segment."""
    from sim_bridge.families import family
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.learning.readout import readout_from_checkpoint_bytes

    readout = readout_from_checkpoint_bytes(Path(deployed).read_bytes())
    if readout is None:
        return SeenContexts(detail=f'{Path(deployed).name} stores no context read-out '
                                   '(zeus export --readout-steps adds one)')
    agent = InferenceAgent.from_checkpoint(deployed)
    if agent.obs_kind != 'state':
        return SeenContexts(detail='the read-out of recorded pixel histories is not supported')
    try:
        specs = {spec.name: spec for spec in family(dataset.task).specs}
    except (KeyError, ValueError):  # a robot task: no declared family ranges to clip to
        specs = {}
    if specs and not set(readout.names) <= set(specs):
        return SeenContexts(detail=f'the read-out estimates {readout.names}, {dataset.task} '
                                   f'has {tuple(specs)}')
    total = sum(ep.num_transitions for ep in dataset.episodes)
    stride = max(1, total // max_steps)
    estimates: list[np.ndarray] = []
    for episode in dataset.episodes:
        history, groups = agent.new_history(), {}
        for t in range(episode.num_transitions):
            history.push(episode.obs[t], episode.action[t], float(episode.reward[t]),
                         episode.obs[t + 1])
            if len(history) >= agent.k and t % stride == 0:
                psi = agent.context(history)
                groups.setdefault(int(episode.segment[t + 1]), []).append(readout.apply(psi))
        estimates += [np.mean(values, axis=0) for values in groups.values()]
    if not estimates:
        return SeenContexts(detail=f'no recorded history reached k={agent.k} steps')
    rows = np.array(estimates)
    if specs:
        rows = np.clip(rows, [specs[n].low for n in readout.names],
                       [specs[n].high for n in readout.names])
    return SeenContexts(spread_rows(rows, readout.names, max_values), 'read-out',
                        f'{len(estimates)} segment(s) read out by {Path(deployed).name} '
                        f'(held-out R^2 {", ".join(f"{r:.2f}" for r in readout.heldout_r2)})')


def seen_contexts(deployed: Path | str, dataset: Any, max_values: int) -> SeenContexts:
    """The recording's true contexts; without truth, the deployed checkpoint's read-out."""
    truth = truth_contexts(dataset, max_values)
    if truth:
        return SeenContexts(truth, 'truth', "the recording's context truth")
    if not dataset.episodes:
        return SeenContexts(detail='the recording holds no episodes')
    return readout_contexts(deployed, dataset, max_values)
