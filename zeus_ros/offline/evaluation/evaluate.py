"""Evaluation of a checkpoint in-process, on the deployment path the nodes use (`zeus eval`).

Every step goes through ScheduledEnv -> rollout.AgentPolicy (InferenceAgent + ContextHistory,
fed like the context_estimator node) -> action, so evaluation measures what runs on the robot.
Reported, per split (train / interpolation / extrapolation value lists of the paper):
  - return per context value, one constant context per episode, next to a random policy;
  - return under unannounced mid-episode switches, and the adaptation latency: steps after a
    switch until the per-step reward (mean of the last 10 steps) is back within 10% of its
    steady value on the new context (the constant-context run's second-half mean);
  - the Spearman rank correlation between pairwise distances of the mean learned context per
    value and of the true contexts (paper section 6.3), with both distance heat maps;
  - the identifiability probe of appendix B.2 (probe.py) on random-policy data;
  - the adaptation diagnostics of diagnostics.py: context sensitivity, spread / noise of the
    context, and the value of adaptation (return with the context live minus frozen, paired).
`values=` evaluates any values of the task's context parameters instead of a preset split.
The command line is zeus_ros/cli/evaluate.py.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import hashlib
import json
from pathlib import Path
import time
from typing import Any

import numpy as np
from tqdm import tqdm

from sim_bridge.presets import SPLITS
from zeus_ros.atomic_file import replace_text
from zeus_ros.labels import context_label
from zeus_ros.offline.evaluation.metrics import plot_heatmaps, write_csv
from zeus_ros.offline.evaluation.probe import ProbeResult, Rollout, probe_context
from zeus_ros.offline.evaluation.records import checkpoint_sha256, write_record
from zeus_ros.offline.rollout import AgentPolicy, Policy, Trace, random_policy, run_steps

__all__ = ['SPLITS', 'adaptation_latencies', 'context_rank_correlation', 'evaluate',
           'evaluate_contexts', 'make_env', 'mid_episode_switches', 'parse_values',
           'split_values', 'switch_schedule', 'switching_order']

RECOVERY_TOLERANCE = 0.10
"""A switch is absorbed once the reward is within 10% of its steady value on the new context."""
NEGLIGIBLE_REWARD = 1e-3
"""Steady per-step rewards below this (in magnitude) give no adaptation latency: see below."""
SMOOTHING = 10
"""Per-step rewards are averaged over this many steps (about one cheetah stride, so the gait's
own oscillation is not read as a disturbance) before the recovery test; latencies are >= 9."""


# ---------------------------------------------------------------------- environment side
def split_values(task: str, split: str) -> list[dict[str, float]]:
    """The context values of a split of the paper's tables, as one mapping per value."""
    from sim_bridge.families import load_preset

    if split not in SPLITS:
        raise ValueError(f'split must be one of {", ".join(SPLITS)}, got {split!r}')
    return load_preset(task, split)


def default_switch_every(task: str) -> int:
    """Steps between switches in the switching run: 100, at most a quarter of an episode."""
    from sim_bridge.registry import task_class

    return max(1, min(100, int(task_class(task).episode_length) // 4))


def make_env(task_name: str, schedule: dict[str, Any], seed: int) -> tuple[Any, Any]:
    """(env, task): task `task_name` seeded `seed`, its context following `schedule`."""
    from sim_bridge.env import ScheduledEnv
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config

    task = make_task(task_name, seed=seed)
    return ScheduledEnv(task, schedule_from_config(schedule, task, seed)), task


def switch_schedule(values: Sequence[dict[str, float]], every: int) -> dict[str, Any]:
    """Cycle through `values`, switching every `every` steps, unannounced."""
    return {'kind': 'switch', 'every': int(every), 'values': [dict(v) for v in values]}


def _policy(agent: Any, task: Any, seed: int, frozen: np.ndarray | None = None,
            blind_steps: int = 0, live_steps: int = 0,
            context_transform: Callable[[np.ndarray], np.ndarray] | None = None,
            context_lag: int = 0) -> Policy:
    if agent is None:
        return random_policy(task, seed)
    return AgentPolicy(agent, noise=0.0, seed=seed, frozen_context=frozen,
                       blind_steps=blind_steps, live_steps=live_steps,
                       context_transform=context_transform, context_lag=context_lag)


def evaluate_contexts(agent: Any, values: Sequence[dict[str, float]], *, episodes: int = 1,
                      seed: int = 0, task_name: str | None = None, progress: bool = True,
                      traces: list[Trace] | None = None,
                      frozen: Sequence[np.ndarray] | None = None,
                      blind_steps: int = 0, live_steps: int = 0,
                      context_transform: Callable[[np.ndarray], np.ndarray] | None = None,
                      context_lag: int = 0, desc: str = 'contexts') -> list[dict[str, Any]]:
    """Deterministic episodes at a constant context per value; one row per episode.

    `agent` is an InferenceAgent, or None for the uniform random policy (task_name needed).
    The environment of value i is seeded with seed + i, so two calls with the same seed meet
    the same initial states (paired comparisons); `frozen[i]` replaces the live context of
    value i at every step, or with `blind_steps` only in the first that many of each episode,
    or with `live_steps` only after the first that many; `context_transform` maps the live
    context before the policy acts and `context_lag` acts on an older one (AgentPolicy).
    `desc` names the phase on its progress bar (steps of all values).
    """
    name = agent.task if agent is not None else task_name
    rows = []
    bar = tqdm(desc=desc, unit='step', disable=not progress)
    for index, value in enumerate(values):
        env, task = make_env(name, {'kind': 'constant', 'context': dict(value)}, seed + index)
        steps = episodes * task.episode_length + 1
        if bar.total is None:  # known once a task is built
            bar.total = steps * len(values)
            bar.refresh()
        try:
            policy = _policy(agent, task, seed + index,
                             None if frozen is None else frozen[index], blind_steps,
                             live_steps, context_transform, context_lag)
            trace = run_steps(env, task, policy, steps, bar=bar)
        finally:
            task.close()
        if traces is not None:
            traces.append(trace)
        for episode, ret in enumerate(trace.episode_returns()[:episodes]):
            rows.append({**{f'context/{k}': v for k, v in value.items()},
                         'episode': episode, 'return': ret})
    bar.close()
    return rows


# ---------------------------------------------------------------------- analysis
def steady_reward(trace: Trace) -> float:
    """Mean per-step reward of the second half of the first episode (after start-up)."""
    starts = [*list(np.flatnonzero(trace.first)), len(trace.reward)]
    rewards = trace.reward[starts[0] + 1:starts[1]]
    return float(rewards[len(rewards) // 2:].mean())


SWITCH_COLUMNS = ('step', 'from', 'to', 'steady_reward', 'latency', 'recovered', 'judged')
"""switches.csv: one row per mid-episode switch; `judged` says why one has no latency."""


def mid_episode_switches(trace: Trace, steady: dict[tuple[float, ...], float]
                         ) -> list[dict[str, Any]]:
    """One row per mid-episode switch (each one switching.png marks), with its latency.

    Latency: steps until the smoothed reward is back near its steady value on the new context.
    A switch whose segment ends (next switch or episode end) first is censored: the segment
    length, not recovered. Not judged (latency and recovered left empty, `judged` says why): a
    switch to a context where the policy's steady reward is negligible (|r| < 1e-3 per step,
    e.g. a finger that never spins: a reward that stays 0 would read as instant recovery), or
    one cut off by the end of the run after fewer than SMOOTHING steps.
    """
    rows = []
    episode = np.cumsum(trace.first)
    boundaries = np.flatnonzero(np.diff(trace.segment) != 0) + 1
    for s in boundaries:
        if trace.first[s]:
            continue
        key = tuple(np.round(trace.context[s], 6))
        target = steady.get(key)
        row: dict[str, Any] = {
            'step': int(s), 'from': float(trace.context[s - 1][0]),
            'to': float(trace.context[s][0]),
            'steady_reward': float('nan') if target is None else target,
            'latency': None, 'recovered': None, 'judged': 'yes'}
        rows.append(row)
        if target is None or abs(target) < NEGLIGIBLE_REWARD:
            row['judged'] = 'no: steady reward ~0 on the new context'
            continue
        end = s + 1
        while end < len(trace.reward) and trace.segment[end] == trace.segment[s] \
                and episode[end] == episode[s]:
            end += 1
        if end - s < SMOOTHING:
            row['judged'] = 'no: cut off by the end of the run'
            continue
        tolerance = RECOVERY_TOLERANCE * abs(target)
        latency, recovered = end - s, False
        for t in range(s, end):
            window = trace.reward[max(s, t - SMOOTHING + 1):t + 1]
            if t - s + 1 >= SMOOTHING and abs(window.mean() - target) <= tolerance:
                latency, recovered = t - s, True
                break
        row.update(latency=latency, recovered=recovered)
    return rows


def adaptation_latencies(trace: Trace, steady: dict[tuple[float, ...], float]
                         ) -> list[dict[str, Any]]:
    """The judged switches of mid_episode_switches: those with an adaptation latency."""
    return [row for row in mid_episode_switches(trace, steady) if row['judged'] == 'yes']


def context_rank_correlation(true: np.ndarray, learned: np.ndarray
                             ) -> tuple[float, np.ndarray, np.ndarray]:
    """Spearman rho between upper-triangle pairwise distances of true and learned contexts."""
    from scipy.spatial.distance import pdist, squareform
    from scipy.stats import spearmanr

    d_true, d_learned = pdist(np.asarray(true, float)), pdist(np.asarray(learned, float))
    rho = float('nan') if len(d_true) < 2 else float(spearmanr(d_true, d_learned).statistic)
    return rho, squareform(d_true), squareform(d_learned)


def mean_context_per_value(traces: Sequence[Trace], k: int) -> np.ndarray | None:
    """Mean psi over the steps of each trace whose history was full (None without psi)."""
    means = []
    for trace in traces:
        if trace.psi is None or trace.psi.shape[1] == 0:
            return None
        full = trace.history_length >= k
        means.append(trace.psi[full].mean(0))
    return np.stack(means)


# ---------------------------------------------------------------------- the command
def random_rollout(task_name: str, values: Sequence[dict[str, float]], steps: int, *,
                   every: int, seed: int, progress: bool = True) -> Rollout:
    """Random-policy steps switching through `values` every `every` steps (probe data)."""
    env, task = make_env(task_name, switch_schedule(values, every), seed)
    try:
        trace = run_steps(env, task, random_policy(task, seed), steps, desc='probe data',
                          progress=progress)
    finally:
        task.close()
    return Rollout(obs=trace.obs, action=trace.action, context=trace.context,
                   first=trace.first, segment=trace.segment)


def parse_values(text: str, names: Sequence[str]) -> list[dict[str, float]]:
    """'0.5,0.8' (one context parameter) or 'a=1:b=2,a=3:b=4' -> one mapping per value."""
    values = []
    for item in (part.strip() for part in text.split(',')):
        if not item:
            continue
        try:
            if '=' not in item:
                if len(names) != 1:
                    raise ValueError(f'this task has {len(names)} context parameters '
                                     f'({", ".join(names)}): write name=value:name=value')
                values.append({names[0]: float(item)})
                continue
            pairs = dict(pair.split('=', 1) for pair in item.split(':'))
            value = {name: float(pairs.pop(name)) for name in names}
        except KeyError as missing:
            raise ValueError(f'--values {item!r}: no value for {missing}') from None
        except ValueError as error:
            raise ValueError(f'--values {item!r}: {error}') from None
        if pairs:
            raise ValueError(f'--values {item!r}: unknown parameter(s) {", ".join(pairs)}; '
                             f'this task has {", ".join(names)}')
        values.append(value)
    if not values:
        raise ValueError('--values: give at least one value, e.g. --values 0.5,0.8')
    bad = [v for v in values if not all(np.isfinite(list(v.values())))]
    if bad:
        raise ValueError(f'--values: not finite: {bad[0]}')
    return values


def train_mean_context(agent: Any, *, episodes: int, seed: int,
                       progress: bool = False) -> np.ndarray | None:
    """The agent's mean context over its task's train values: what it acts on in training.

    Same protocol as the split's episodes (deterministic, `episodes` per value, `seed`).
    """
    traces: list[Trace] = []
    evaluate_contexts(agent, split_values(agent.task, 'train'), episodes=episodes, seed=seed,
                      progress=progress, traces=traces, desc='train values (mean context)')
    return overall_mean_context(agent, traces)


def overall_mean_context(agent: Any, traces: Sequence[Trace]) -> np.ndarray | None:
    """The mean over values of each trace's mean context; None without a context."""
    from zeus_ros.offline.evaluation.diagnostics import mean_contexts

    means = mean_contexts(agent, traces)
    return None if means is None else np.mean(means, axis=0)


TRAIN_MEAN_FILE = 'train_mean_context.json'
"""Beside a run's eval_<split> folders: the train-mean context, so each split needs it once."""


def _train_mean_key(checkpoint: Path, episodes: int, seed: int) -> dict[str, Any]:
    digest = hashlib.sha256(Path(checkpoint).read_bytes()).hexdigest()
    return {'checkpoint_sha256': digest, 'episodes': episodes, 'seed': seed}


def cached_train_mean_context(agent: Any, checkpoint: Path, folder: Path, *, episodes: int,
                              seed: int, progress: bool = False) -> np.ndarray | None:
    """train_mean_context, read from `folder` when this checkpoint and protocol stored it there.

    `zeus eval --split all` evaluates every split in its own job and each held-out split needs
    the train values' mean context: without this every split rolls the train values out again.
    """
    key = _train_mean_key(checkpoint, episodes, seed)
    path = folder / TRAIN_MEAN_FILE
    try:
        stored = json.loads(path.read_text())
        if stored['key'] == key:
            return None if stored['context'] is None else np.asarray(stored['context'])
    except (OSError, ValueError, KeyError, TypeError):
        pass  # missing, from another checkpoint or protocol, or unreadable: compute it
    mean = train_mean_context(agent, episodes=episodes, seed=seed, progress=progress)
    store_train_mean_context(mean, key, folder)
    return mean


def store_train_mean_context(mean: np.ndarray | None, key: dict[str, Any], folder: Path
                             ) -> None:
    """Write the train-mean context for cached_train_mean_context, atomically.

    Two split jobs may store it at once (with identical contents).
    """
    replace_text(folder / TRAIN_MEAN_FILE, json.dumps(
        {'key': key, 'context': None if mean is None else np.asarray(mean).tolist()}))


def switching_order(values: Sequence[dict[str, float]], seed: int) -> list[dict[str, float]]:
    """The split's values in a seeded shuffled order (no neighbour-to-neighbour sweep)."""
    order = np.random.default_rng(seed).permutation(len(values))
    return [dict(values[i]) for i in order]


def default_out(checkpoint: str | Path, split: str) -> Path:
    """Where an evaluation goes without --out: eval_<split>/ beside the checkpoint.

    `zeus export` and `zeus report` look there (and in any folder below the run's) by default.
    """
    return Path(checkpoint).parent / f'eval_{split}'


def evaluate(checkpoint: str | Path, *, split: str, task: str | None = None,
             episodes: int = 3, switch_every: int | None = None, switch_episodes: int = 1,
             probe_steps: int = 4000, seed: int = 0, out: str | Path | None = None,
             progress: bool = True, values: Sequence[dict[str, float]] | None = None,
             diagnostics: bool = True, expect_sha256: str | None = None) -> dict[str, Any]:
    """Run the whole evaluation of one checkpoint on one split; write CSV/PNG into `out`.

    `expect_sha256`: refuse the file unless it has this sha256 (besides what its card,
    sidecar or the zoo index record: zeus_ros/integrity.py).

    `values` replaces the split's preset values (then `split` only labels the outputs).
    `switch_every` None: every 100 steps, or a quarter episode for shorter episodes (40-step
    Cheetah-Run-v1 switches every 10 steps).
    """
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.diagnostics import (
        context_sensitivity,
        frozen_contexts,
        policy_contexts,
        spread_over_noise,
    )
    from zeus_ros.offline.evaluation.metrics import plot_bars, plot_trace

    started = time.perf_counter()
    agent = InferenceAgent.from_checkpoint(checkpoint, expect_task=task,
                                           expect_sha256=expect_sha256)
    out = Path(out) if out is not None else default_out(checkpoint, split)
    values_given = values is not None
    values = split_values(agent.task, split) if values is None else list(values)
    name = agent.context_names[0]
    labels = [', '.join(f'{v:g}' for v in value.values()) for value in values]
    traces: list[Trace] = []
    rows = [{'policy': 'agent', **r} for r in evaluate_contexts(
        agent, values, episodes=episodes, seed=seed, progress=progress, traces=traces,
        desc='agent')]
    rows += [{'policy': 'random', **r} for r in evaluate_contexts(
        None, values, episodes=episodes, seed=seed, task_name=agent.task, progress=progress,
        desc='random policy')]
    steady = {tuple(np.round(list(v.values()), 6)): steady_reward(t)
              for v, t in zip(values, traces, strict=True)}
    if switch_every is None:
        switch_every = default_switch_every(agent.task)
    env, sim = make_env(agent.task, switch_schedule(switching_order(values, seed),
                                                      switch_every), seed)
    try:
        switching = run_steps(env, sim, AgentPolicy(agent, noise=0.0, seed=seed),
                              switch_episodes * sim.episode_length + 1, desc='switching',
                              progress=progress)
    finally:
        sim.close()
    switches = mid_episode_switches(switching, steady)
    judged = [s for s in switches if s['judged'] == 'yes']
    learned = mean_context_per_value(traces, agent.k)
    true = np.asarray([list(v.values()) for v in values], float)
    rho = float('nan')
    if learned is not None:
        rho, d_true, d_learned = context_rank_correlation(true, learned)
        plot_heatmaps({'true context distance': d_true, 'learned context distance': d_learned},
                      labels, out / 'context_distances.png',
                      title=f'{agent.task} {split}: Spearman rho = {rho:.3f}',
                      axis_label=', '.join(context_label(n) for n in agent.context_names),
                      units=('distance (context units)', 'distance in psi space'))
    probe: ProbeResult | None = None
    if probe_steps > 0:
        rollout = random_rollout(agent.task, values, probe_steps, every=50, seed=seed + 1,
                                 progress=progress)
        probe = probe_context([rollout], k=5, seed=seed, progress=progress)
    nan = float('nan')
    sensitivity, (_, _, spread_noise) = nan, (nan, nan, nan)
    adaptation = {'other': nan, 'mean': nan, 'train_mean': nan, 'steady': nan}
    train_mean = None
    on_train_values = split == 'train' and not values_given
    if diagnostics and agent.context_dim and not on_train_values:
        train_mean = cached_train_mean_context(agent, checkpoint, out.parent,
                                               episodes=episodes, seed=seed, progress=progress)
    elif diagnostics and agent.context_dim:  # the train split's own traces give it
        store_train_mean_context(overall_mean_context(agent, traces),
                                 _train_mean_key(checkpoint, episodes, seed), out.parent)
    frozen = frozen_contexts(agent, traces, values, train_mean) if diagnostics else None
    if diagnostics:
        sensitivity = context_sensitivity(agent, traces, values)
        spread_noise = spread_over_noise([policy_contexts(t, agent) for t in traces])[2]
    live = np.asarray([r['return'] for r in rows if r['policy'] == 'agent'])
    for kind, contexts in (frozen or {}).items():
        frozen_rows = evaluate_contexts(agent, values, episodes=episodes, seed=seed,
                                        progress=progress, frozen=contexts,
                                        desc=f'frozen_{kind}')
        rows += [{'policy': f'frozen_{kind}', **r} for r in frozen_rows]
        adaptation[kind] = float(np.mean(live - np.asarray([r['return'] for r in frozen_rows])))
    if on_train_values:  # the split's mean is the train values' mean
        adaptation['train_mean'] = adaptation['mean']
    steady_anchor = (frozen or {}).get('mean' if on_train_values else 'train_mean')
    if steady_anchor is not None:  # frozen there only once psi's history is full
        steady_rows = evaluate_contexts(agent, values, episodes=episodes, seed=seed,
                                        progress=progress, frozen=steady_anchor,
                                        live_steps=agent.k, desc='frozen_steady')
        rows += [{'policy': 'frozen_steady', **r} for r in steady_rows]
        adaptation['steady'] = float(np.mean(live - np.asarray([r['return']
                                                               for r in steady_rows])))
    agent_ret = [r['return'] for r in rows if r['policy'] == 'agent']
    random_ret = [r['return'] for r in rows if r['policy'] == 'random']
    recovered = [s['latency'] for s in judged if s['recovered']]
    summary = [{
        'policy': 'agent', 'method': agent.method, 'split': split,
        'mean_return': float(np.mean(agent_ret)), 'std_return': float(np.std(agent_ret)),
        'switching_return': float(np.mean(switching.episode_returns()[:switch_episodes])),
        'switches': len(switches), 'judged': len(judged), 'recovered': len(recovered),
        'mean_latency': float(np.mean(recovered)) if recovered else float('nan'),
        'spearman': rho,
        'probe_mse': probe.mse if probe else float('nan'),
        'probe_mean_mse': probe.baseline_mse if probe else float('nan'),
        'sensitivity': sensitivity, 'spread_noise': spread_noise,
        'adaptation_value_other': adaptation['other'],
        'adaptation_value_mean': adaptation['mean'],
        'adaptation_value_train_mean': adaptation['train_mean'],
        'adaptation_value_steady': adaptation['steady'], 'episodes': episodes},
        {'policy': 'random', 'method': 'uniform', 'split': split,
         'mean_return': float(np.mean(random_ret)), 'std_return': float(np.std(random_ret))}]
    write_csv(out / 'contexts.csv', rows)
    write_csv(out / 'switches.csv', switches, columns=SWITCH_COLUMNS)
    write_csv(out / 'summary.csv', summary)
    policies = ['agent', *(f'frozen_{kind}' for kind in frozen or {}),
                *(['frozen_steady'] if steady_anchor is not None else []), 'random']
    per_value = {policy: [float(np.mean([r['return'] for r in rows if r['policy'] == policy
                                         and r[f'context/{name}'] == v[name]]))
                          for v in values] for policy in policies}
    plot_bars(labels, per_value, out / 'returns.png',
              xlabel=', '.join(context_label(n) for n in agent.context_names),
              ylabel='episode return',
              title=f'{agent.task} {split}: return per context value ({agent.method})')
    plot_trace(switching.reward, {context_label(name, 'true '): switching.context[:, 0]},
               marks=[s['step'] for s in switches], path=out / 'switching.png',
               title=f'{agent.task} {split}: per-step reward, {len(switches)} switches every '
               f'{switch_every} steps ({len(judged)} judged, {len(recovered)} recovered)')
    # Last: the record says this folder is complete (export's card and report read it).
    write_record(out, checkpoint, sha256=checkpoint_sha256(checkpoint), task=agent.task,
                 method=agent.method, seed=int(agent.agent.config.seed), split=split,
                 seconds=time.perf_counter() - started)
    return {'out': out, 'summary': summary, 'per_value': per_value, 'values': labels,
            'switches': switches, 'probe': probe}
