"""Rollouts in-process: the twin of the live loop that collection, evaluation and training share.

A policy answers each control step as the context_estimator + policy nodes would
(`random_policy`, `AgentPolicy`); `collect` writes the steps to a bag exactly as the recorder
does (same topics, types, header stamps = simulation time, step indices), so training cannot
tell the two apart; `run_steps` keeps them in memory as a `Trace` for evaluation.
It sits below offline/training and offline/evaluation and above the bag format.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
import contextlib
from dataclasses import dataclass
import itertools
from pathlib import Path
import shutil
import time
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm
import yaml

from zeus_ros.bags.schema import StepFeedbackFields, ns_from_sim_time
from zeus_ros.bags.writer import SimStep, StepBagWriter
from zeus_ros.offline.schedule_text import DEFAULT_SCHEDULE, SCHEDULE_HELP

if TYPE_CHECKING:
    from zeus_ros.learning.inference import InferenceAgent

__all__ = ['DEFAULT_SCHEDULE', 'SCHEDULE_HELP', 'AgentPolicy', 'CollectDiskFull', 'CollectStats',
           'Policy', 'PolicyDecision', 'Trace', 'collect', 'disk_full_line', 'next_bag_path',
           'parse_schedule', 'random_policy', 'record_step', 'run_steps']

@dataclass(frozen=True)
class CollectStats:
    """What one collection run wrote."""

    bag: Path
    steps: int
    episodes: int
    seconds: float
    bytes_written: int

    @property
    def steps_per_s(self) -> float:
        """Control steps written per wall-clock second."""
        return self.steps / max(self.seconds, 1e-9)


@dataclass(frozen=True)
class PolicyDecision:
    """A policy's answer to one step: the action, and psi(H) when it estimates a context."""

    action: np.ndarray
    context: np.ndarray | None = None
    history_length: int = 0


Policy = Callable[[Any, SimStep], PolicyDecision]
"""policy(env_step, sim_step) -> PolicyDecision; the SimStep holds the frame when recording."""


def parse_schedule(text: str) -> dict[str, Any]:
    """A schedule config dict from a YAML file path or the inline form.

    The forms are listed in SCHEDULE_HELP (`zeus collect --help` prints it).
    """
    path = Path(text)
    if path.suffix in {'.yaml', '.yml'} or path.is_file():
        if not path.is_file():
            raise ValueError(f'--schedule: no such YAML file {path}')
        try:
            config = yaml.safe_load(path.read_bytes().decode('utf-8'))
        except UnicodeDecodeError as error:
            raise ValueError(f'--schedule: {path} is not a text file (byte '
                             f'{error.object[error.start]:#04x} at offset {error.start} is not '
                             'UTF-8)') from None
        except yaml.YAMLError as error:
            mark = getattr(error, 'problem_mark', None)
            where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
            raise ValueError(f'--schedule: {path} is not valid YAML{where}: '
                             f'{getattr(error, "problem", None) or error}') from None
        if not isinstance(config, dict):
            kind = type(config).__name__
            raise ValueError(f'--schedule: {path} must hold a mapping, got {kind}')
        return config
    parts = text.split(':')
    if not parts[0] or not parts[0].replace('_', '').isalpha():
        raise ValueError(f'--schedule {text!r}: expected KIND[:PRESET][:KEY=VALUE,...]')
    config: dict[str, Any] = {'kind': parts[0]}
    rest = parts[1:]
    if rest and '=' not in rest[0]:
        config['values'] = rest.pop(0)
    if len(rest) > 1:
        raise ValueError(f'--schedule {text!r}: give options as one KEY=VALUE,KEY=VALUE list')
    for item in rest[0].split(',') if rest and rest[0] else []:
        key, sep, value = item.partition('=')
        if not sep or not key:
            raise ValueError(f'--schedule {text!r}: option {item!r} is not KEY=VALUE')
        config[key] = yaml.safe_load(value)
    return config


class CollectDiskFull(Exception):  # noqa: N818 - named as what the user reads
    """A full disk in a collect worker, as its one line (picklable: it crosses processes)."""


def disk_full_line(error: BaseException, bag: Path, writer: StepBagWriter | None,
                   steps: int) -> str | None:
    """A full disk as one line (None for any other error); the half-written bag is removed.

    The space needed is what the steps written so far took, scaled to all `steps`.
    """
    from zeus_ros.atomic_file import disk_full, free_space, size_text
    from zeus_ros.bags.schema import TOPIC_STEP

    if disk_full(error) is None:
        return None
    if writer is not None:
        with contextlib.suppress(Exception):  # closing a bag on a full disk fails again
            writer.close()
    shutil.rmtree(bag, ignore_errors=True)
    done = writer.counts.get(TOPIC_STEP, 0) if writer is not None else 0
    need = (f'{steps} steps need about {size_text(writer.bytes_written * steps // done)}, '
            if writer is not None and done else '')
    return (f'no space left on the device writing {bag}: {need}{size_text(free_space(bag.parent))}'
            ' free there; nothing was kept (the half-written bag is removed)')


def next_bag_path(out: Path, *, append: bool) -> Path:
    """Where the new bag goes: out/bag_NNN; refuse to mix with existing bags unless appending."""
    existing = sorted(p for p in out.glob('bag_*') if p.is_dir()) if out.is_dir() else []
    if existing and not append:
        raise FileExistsError(f'{out} already holds {len(existing)} bag(s) ({existing[-1].name} '
                              '...); pass --append to add one, or choose another --out')
    numbers = [int(p.name[4:]) for p in existing if p.name[4:].isdigit()]
    return out / f'bag_{max(numbers, default=-1) + 1:03d}'


class _LogClock:
    """Monotonic bag times from stamps that restart at 0 on every episode reset."""

    def __init__(self) -> None:
        self.offset = 0
        self.last = -1

    def __call__(self, stamp_ns: int) -> int:
        if stamp_ns + self.offset <= self.last:
            self.offset = self.last + 1 - stamp_ns
        self.last = stamp_ns + self.offset
        return self.last


def record_step(es: Any, task: Any, pixels: bool) -> SimStep:
    """The SimStep the sim_bridge node publishes for one EnvStep."""
    obs = es.observation
    applied = es.applied_action
    names = tuple(obs.context)
    return SimStep(
        step=int(es.step),
        stamp_ns=ns_from_sim_time(es.sim_time),
        state=obs.state,
        feedback=StepFeedbackFields(
            episode=int(es.episode),
            episode_step=int(es.episode_step),
            first=bool(obs.first),
            last=bool(obs.last),
            reward=float(obs.reward),
            applied_action=np.zeros(0, np.float32) if applied is None else applied,
            action_status=int(es.status),
            task=task.name,
        ),
        context_names=names,
        context_values=np.asarray([obs.context[n] for n in names], np.float64),
        segment=int(es.segment),
        frame=task.render(84, 84) if pixels else None,
    )


def collect(
    env: Any,
    task: Any,
    policy: Policy,
    writer: StepBagWriter,
    steps: int,
    *,
    progress: bool = True,
) -> CollectStats:
    """Run `steps` control steps of `env`, writing each step's messages and the policy's action.

    `policy(env_step, record)` answers the observation of every step, as the policy node
    does; after a `last` observation the env starts the next episode itself (time limit).
    """
    clock = _LogClock()
    start = time.perf_counter()
    episodes = 0
    es = env.reset()
    with tqdm(total=steps, disable=not progress, unit='step', desc='collect') as bar:
        for n in range(steps):
            rec = record_step(es, task, writer.pixels)
            log = clock(rec.stamp_ns)
            writer.write_step(rec, log_ns=log)
            episodes += int(rec.feedback.first)
            bar.update(1)
            out = policy(es, rec)
            action = np.asarray(out.action, np.float32)
            if out.context is not None and out.context.size:
                writer.write_estimate(rec.step, rec.stamp_ns, out.context, out.history_length,
                                      log_ns=log)
            writer.write_action(rec.step, rec.stamp_ns, action, log_ns=log)
            if n < steps - 1:
                es = env.step(action)
    return CollectStats(writer.path, steps, episodes, time.perf_counter() - start,
                        writer.bytes_written)


def random_policy(task: Any, seed: int) -> Policy:
    """Uniform actions inside the task's bounds, from a seeded generator."""
    low, high = task.action_bounds
    rng = np.random.default_rng(seed)
    return lambda _es, _rec: PolicyDecision(rng.uniform(low, high).astype(np.float32))


class AgentPolicy:
    """A checkpointed agent acting as the context_estimator + policy nodes would, plus noise.

    The history is fed with the applied action and reward from each step's feedback (what the
    estimator node sees), and cleared at episode starts.
    """

    def __init__(self, agent: InferenceAgent, *, noise: float, seed: int,
                 stochastic: bool = False,
                 frozen_context: np.ndarray | None = None, blind_steps: int = 0,
                 live_steps: int = 0,
                 context_transform: Callable[[np.ndarray], np.ndarray] | None = None,
                 context_lag: int = 0) -> None:
        """Wrap `agent`; options for training collection and for diagnostics.

        `stochastic` samples the SAC policy (seeded torch RNG) instead of taking its mode;
        `frozen_context` replaces the live context at every step (the value-of-adaptation
        diagnostic: what the policy earns when it cannot follow the context), or with
        `blind_steps` > 0 only for that many steps after each episode start and each change of
        the true context (the inference-delay yardstick: an oracle that, like any estimator,
        must first see a context before it knows it), or with `live_steps` > 0 only from that
        many steps after each episode start on (the value of adaptation once psi's history is
        full: what psi's start-of-episode signal earns is not counted as adaptation).
        `context_transform` maps the live context before the policy acts on it (guards for
        contexts beyond the training range). `context_lag` L acts on step k with the context
        estimated at step k - L (never one from before the episode's first step), as the policy
        node does with its `context_lag` parameter.
        """
        import torch

        from zeus_ros.learning.frames import FrameStack  # torch: only when a checkpoint acts
        from zeus_ros.learning.inference import MAX_CONTEXT_LAG

        if not 0 <= context_lag <= MAX_CONTEXT_LAG:
            raise ValueError(f'context_lag={context_lag}: must be between 0 and '
                             f'{MAX_CONTEXT_LAG}')
        for name, steps in (('blind_steps', blind_steps), ('live_steps', live_steps)):
            if steps < 0 or (steps > 0 and frozen_context is None):
                raise ValueError(f'{name}={steps}: needs a frozen_context to act on, and must '
                                 'be >= 0')
        if blind_steps and live_steps:
            raise ValueError('blind_steps and live_steps: give one (frozen first, or frozen '
                             'after)')
        self.agent = agent
        self.noise = noise
        self.stochastic = stochastic
        if stochastic:
            torch.manual_seed(seed)
        self.frozen_context = (None if frozen_context is None
                               else np.asarray(frozen_context, np.float32))
        self.blind_steps = int(blind_steps)
        self.live_steps = int(live_steps)
        self._episode_step = 0
        self.context_transform = context_transform
        self._seen: tuple[np.ndarray | None, int] = (None, 0)  # true context, steps known
        self.rng = np.random.default_rng(seed)
        self.history = agent.new_history()
        self.frames = FrameStack() if agent.obs_kind == 'pixels' else None
        self._prev: np.ndarray | None = None
        # This episode's newest L + 1 estimates; the oldest is the one acted on.
        self._recent: deque[np.ndarray | None] = deque(maxlen=int(context_lag) + 1)

    def _observation(self, es: Any, rec: SimStep) -> np.ndarray:
        if self.frames is None:
            return np.asarray(es.observation.state, np.float32)
        if rec.frame is None:
            raise ValueError('a pixel checkpoint needs frames: run zeus collect with --pixels')
        if es.observation.first:
            return self.frames.reset(rec.frame)
        return self.frames.push(rec.frame)

    def __call__(self, es: Any, rec: SimStep) -> PolicyDecision:
        """Update H with the step's transition, estimate psi(H) and act on o_k."""
        obs = self._observation(es, rec)
        if es.observation.first or self._prev is None:
            self.history.clear()
            self._recent.clear()
            self._episode_step = 0
        else:
            self.history.push(self._prev, es.applied_action, es.observation.reward, obs)
        self._prev = obs
        truth = es.observation.context
        true_ctx = np.asarray([truth[n] for n in self.agent.context_names], np.float32)
        frozen = self.frozen_context is not None and self._blind(true_ctx,
                                                                  es.observation.first)
        if frozen and self._recent.maxlen == 1:
            psi = None  # acts on the frozen context: psi(H) would be computed for nothing
        else:
            psi = self.agent.context(self.history, true_context=true_ctx)
            if self.context_transform is not None and psi is not None:
                psi = np.asarray(self.context_transform(psi), np.float32)
        self._recent.append(psi)
        psi = self.frozen_context if frozen else self._recent[0]
        self._episode_step += 1
        action = self.agent.act(obs, psi, deterministic=not self.stochastic, noise=self.noise,
                                rng=self.rng)
        return PolicyDecision(action, None if self.agent.needs_true_context else psi,
                            len(self.history))


    def _blind(self, true_ctx: np.ndarray, first: bool) -> bool:
        """Whether this step acts on the frozen context (always, without blind/live_steps)."""
        if self.live_steps:
            return self._episode_step >= self.live_steps
        if self.blind_steps == 0:
            return True
        known, steps = self._seen
        if first or known is None or not np.array_equal(known, true_ctx):
            known, steps = true_ctx, 0
        self._seen = (known, steps + 1)
        return steps < self.blind_steps


@dataclass(frozen=True)
class Trace:
    """Per-observation record of a run; reward[i] was earned by the action at i - 1."""

    reward: np.ndarray
    first: np.ndarray
    context: np.ndarray
    segment: np.ndarray
    psi: np.ndarray | None
    history_length: np.ndarray
    obs: np.ndarray
    action: np.ndarray

    def episode_returns(self) -> list[float]:
        """Return of every complete or partial episode (rewards after each start)."""
        starts = [*list(np.flatnonzero(self.first)), len(self.reward)]
        return [float(self.reward[a + 1:b].sum()) for a, b in itertools.pairwise(starts)]


def run_steps(env: Any, task: Any, policy: Policy, steps: int, *, desc: str = '',
              progress: bool = True, bar: tqdm | None = None) -> Trace:
    """Drive `env` for `steps` observations with `policy`, as `collect` does.

    `bar`: a progress bar of a longer phase to advance instead of a bar of its own.
    """
    cols: dict[str, list[Any]] = {k: [] for k in ('reward', 'first', 'context', 'segment',
                                                   'psi', 'hist', 'obs', 'action')}
    es = env.reset()
    names = task.context_names
    own = bar is None
    bar = tqdm(total=steps, desc=desc, unit='step', disable=not progress, leave=False) \
        if own else bar
    for n in range(steps):
        bar.update()
        rec = record_step(es, task, pixels=getattr(policy, 'frames', None) is not None)
        out = policy(es, rec)
        obs = es.observation
        cols['reward'].append(0.0 if obs.first else float(obs.reward))
        cols['first'].append(bool(obs.first))
        cols['context'].append([obs.context[name] for name in names])
        cols['segment'].append(int(es.segment))
        cols['psi'].append(out.context)
        cols['hist'].append(out.history_length)
        cols['obs'].append(np.asarray(obs.state, np.float32))
        cols['action'].append(np.asarray(out.action, np.float32))
        if n < steps - 1:
            es = env.step(out.action)
    if own:
        bar.close()
    psi = None if any(p is None for p in cols['psi']) else np.stack(cols['psi'])
    return Trace(np.asarray(cols['reward']), np.asarray(cols['first']),
                 np.asarray(cols['context'], float), np.asarray(cols['segment']), psi,
                 np.asarray(cols['hist']), np.stack(cols['obs']), np.stack(cols['action']))
