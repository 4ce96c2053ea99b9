"""The gate of a continual round: candidate against deployed, paired, where it matters.

Both checkpoints run in-process on the same initial states per context value (fresh for each
round: the round's `eval_seed`), on the contexts seen in the new splits and on the family's
train values. One decision where the robot runs: the mean paired gain over the seen contexts
must be at least max(`margin`, 2 s.e.), the s.e. that of a mean over these contexts,
stratified by context (each paired episode a sample of its context's difference; with one
episode per value the spread across values stands in): the question is whether the
candidate is better where the robot now runs, not on contexts drawn anew. And a forgetting
budget where it was trained: no train value may lose more than max(`tolerance_floor`,
`tolerance` x |deployed return there|, 2 s.e. of its paired differences). A seen value is
not vetoed on its own: far beyond the range one 40-step episode earns -50 or -200 on a fall.
The round (continual.py) confirms a pass on other fresh initial states.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
import time
from typing import Any

import numpy as np

from zeus_ros.system.continual_settings import ContinualSettings, RoundProgress

__all__ = ['GateResult', 'gate']


@dataclass
class GateResult:
    """Paired candidate-vs-deployed figures and the decision."""

    deploy: bool
    reason: str
    gain: float
    se: float
    required: float
    deployed_seen: float
    candidate_seen: float
    values: list[dict[str, Any]] = field(default_factory=list)
    """Per value: context, where (seen/train), deployed, candidate, diff, allowed."""
    seconds: float = 0.0

    def summary(self) -> str:
        """One line for logs and /diagnostics."""
        worst = min(self.values, key=lambda v: v['diff'] - (-v['allowed']), default=None)
        where = '' if worst is None else (
            f'; tightest {worst["where"]} value {_fmt_context(worst["context"])}: '
            f'{worst["diff"]:+.1f} (allowed -{worst["allowed"]:.1f})')
        return (f'gain on seen contexts {self.gain:+.2f} ± {self.se:.2f} (required '
                f'{self.required:.2f}; deployed {self.deployed_seen:.1f}, candidate '
                f'{self.candidate_seen:.1f}){where}')



def _paired_returns(old: Any, new: Any, values: Sequence[dict[str, float]], seen: int,
                    settings: ContinualSettings, progress: RoundProgress | None, phase: str
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(values, episodes) returns of both checkpoints, value by value on the same seeds.

    Value i runs on seed eval_seed + i for both (evaluate_contexts' own pairing); after
    each value the progress shows the running gain over the seen values done so far.
    """
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts

    before, after = [], []
    for index, value in enumerate(values):
        for agent, out in ((old, before), (new, after)):
            rows = evaluate_contexts(agent, [value], episodes=settings.episodes,
                                     seed=settings.eval_seed + index, progress=False)
            out.append([r['return'] for r in rows])
        if progress is not None:
            diff = np.asarray(after[:seen], float) - np.asarray(before[:seen], float)
            gain = float(diff.mean()) if len(diff) else None
            se = (float(np.sqrt(np.sum(diff.std(1, ddof=1) ** 2 / diff.shape[1])) / len(diff))
                  if len(diff) and diff.shape[1] > 1 else None)
            progress.update(phase, (index + 1) * settings.episodes,
                            len(values) * settings.episodes, gain=gain, gain_se=se)
    return np.asarray(before, float), np.asarray(after, float)


def gate(deployed: Path | str, candidate: Path | str, seen: Sequence[dict[str, float]],
         settings: ContinualSettings, progress: RoundProgress | None = None,
         phase: str = 'gate') -> GateResult:
    """Paired evaluation of both checkpoints on the seen contexts and the train values."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import split_values

    begin = time.perf_counter()
    old = InferenceAgent.from_checkpoint(deployed)
    new = InferenceAgent.from_checkpoint(candidate, expect_task=old.task)
    train = split_values(old.task, 'train')
    if 0 < settings.max_train_values < len(train):
        picks = np.round(np.linspace(0, len(train) - 1, settings.max_train_values))
        train = [train[int(i)] for i in picks]
    values = [*seen, *train]
    where = ['seen'] * len(seen) + ['train'] * len(train)
    episodes_before, episodes_after = _paired_returns(  # paired episode by episode
        old, new, values, len(seen), settings, progress, phase)
    before, after = episodes_before.mean(1), episodes_after.mean(1)
    value_se = ((episodes_after - episodes_before).std(1, ddof=1) / np.sqrt(settings.episodes)
                if settings.episodes > 1 else np.zeros(len(values)))
    diff = after - before
    allowed = np.maximum(np.maximum(settings.tolerance_floor,
                                    settings.tolerance * np.abs(before)), 2 * value_se)
    rows = [{'context': v, 'where': w, 'deployed': float(b), 'candidate': float(a),
             'diff': float(d), 'se': float(e), 'allowed': float(t)}
            for v, w, b, a, d, e, t in zip(values, where, before, after, diff, value_se, allowed,
                                           strict=True)]
    n = len(seen) or len(values)  # no truth recorded: the train values stand in
    seen_diff = diff[:n]
    gain = float(seen_diff.mean())
    if settings.episodes > 1:  # the mean over these contexts, stratified by context
        se = float(np.sqrt(np.sum(value_se[:n] ** 2)) / n)
    else:  # one episode per value: only the spread across values tells the noise
        se = float(seen_diff.std(ddof=1) / np.sqrt(n)) if n > 1 else 0.0
    required = max(settings.margin, 2 * se)
    # One decision where the robot runs (the mean over the seen contexts, above), and the
    # forgetting budget value by value where it was trained (no train value worse than
    # allowed). When no truth was recorded the train values are the seen ones, checked both.
    worse = [r for r in rows if r['where'] == 'train' and r['diff'] < -r['allowed']]
    if gain < required:
        reason = f'gain {gain:+.2f} below the required {required:.2f}'
    elif worse:
        r = min(worse, key=lambda r: r['diff'] + r['allowed'])
        reason = (f'{len(worse)} value(s) worse than allowed, e.g. {r["where"]} '
                  f'{_fmt_context(r["context"])}: {r["diff"]:+.1f} (allowed -{r["allowed"]:.1f})')
    else:
        reason = f'gain {gain:+.2f} >= {required:.2f} and no value worse than allowed'
    return GateResult(gain >= required and not worse, reason, gain, se, required,
                      float(before[:n].mean()), float(after[:n].mean()), rows,
                      time.perf_counter() - begin)


def _fmt_context(context: dict[str, float]) -> str:
    return ','.join(f'{k}={v:g}' for k, v in context.items())
