"""One trial of `zeus sweep`: `zeus loop` then `zeus eval`, as a person would type them.

A trial is the record -> retrain loop of one (task, method, seed, overrides) and its evaluation.

Layout (that of experiments/run_one.sh, which `zeus report` reads):
  <out>/<group>/<method>_s<seed>/config.yaml    the trial's training config, overrides applied
  <out>/<group>/<method>_s<seed>/protocol.yaml  its loop and evaluation flags (LoopProtocol)
  <out>/<group>/<method>_s<seed>/bags, run/      what `zeus loop --out` writes
  <out>/<group>/<method>_s<seed>/state.json     what is finished, with wall seconds
                                                 (offline/runs.py; old .done markers still read)
  <out>/<group>/<method>_s<seed>/eval_<split>/   `zeus eval` output
  <out>/<group>/<method>_s<seed>.log             every attempt's output, appended
  <out>/<group>/<method>_s<seed>.pid             the running step's process id (while it runs)
Each step is a subprocess: a killed or crashed step leaves the worker alive to say so, a
finished trial hands its memory back, and torch's threads follow OMP_NUM_THREADS. Finished
steps are skipped, so running a trial again resumes it (`zeus loop --resume`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
import datetime
from functools import partial
import os
from pathlib import Path
import signal
import socket
import subprocess
import sys
import time
from typing import Any

import yaml

from zeus_ros.offline.runs import mark_evaluated, mark_trained, read_state
from zeus_ros.system.processes import die_with_parent

__all__ = ['LoopProtocol', 'Trial', 'TrialError', 'default_schedule', 'recorded_differences',
           'run_trial', 'trial_done', 'trial_steps']


class TrialError(RuntimeError):
    """A step of a trial failed; the message names the step, how it ended and the log."""


@dataclass(frozen=True)
class LoopProtocol:
    """The `zeus loop` and `zeus eval` flags every trial of a sweep shares (run_one.sh's)."""

    rounds: int = 5
    random_steps: int = 1500
    steps: int = 2000
    updates: int = 2000
    noise: float = 0.2
    schedule: str | None = None
    """None: switch through the train preset every min(100, episode/2) steps."""
    eval_episodes: int | None = None
    """Episodes per context value in evaluation (None: `zeus eval`'s default)."""
    eval_seed: int = 100


@dataclass(frozen=True)
class Trial:
    """One (task, method, seed, overrides) point of the grid and where it writes."""

    task: str
    method: str
    seed: int
    group: str
    folder: Path
    config: dict[str, Any] = field(hash=False)
    splits: tuple[str, ...] = ()
    protocol: LoopProtocol = LoopProtocol()

    @property
    def name(self) -> str:
        """group/method_sSEED: unique within a sweep."""
        return f'{self.group}/{self.folder.name}'

    @property
    def log(self) -> Path:
        """The trial's log (all attempts)."""
        return self.folder.with_name(self.folder.name + '.log')


def default_schedule(task: str) -> str:
    """`zeus loop`'s default schedule (collect.DEFAULT_SCHEDULE), the same for every task.

    `task` stays in the signature so a task-specific default can return without changing callers.
    """
    from zeus_ros.offline.rollout import DEFAULT_SCHEDULE

    del task
    return DEFAULT_SCHEDULE


def recorded_differences(trial: Trial) -> list[str]:
    """What differs between `trial` and what its folder was run with ('key: was -> now').

    A trial folder holds one run: skipping or resuming it under other settings would mix them.
    Folders without a record (experiments/run_one.sh's) are taken as they are.
    """
    differences = []
    for name, wanted in (('config.yaml', trial.config), ('protocol.yaml', asdict(trial.protocol))):
        try:
            stored = yaml.safe_load((trial.folder / name).read_text())
        except OSError:
            continue
        if not isinstance(stored, dict):
            continue
        differences += [f'{key}: {stored.get(key)!r} -> {wanted.get(key)!r}'
                        for key in sorted(set(stored) | set(wanted))
                        if stored.get(key) != wanted.get(key)]
    return differences


def trial_done(trial: Trial) -> bool:
    """Trained and every requested split evaluated."""
    return read_state(trial.folder).done(trial.splits)


def _ended(code: int) -> str:
    if code < 0:
        try:
            return f'was killed by {signal.Signals(-code).name}'
        except ValueError:
            return f'was killed by signal {-code}'
    return f'exited with code {code}'


def _run_step(trial: Trial, what: str, args: list[str], threads: int) -> float:
    """Run `zeus <args>` with its output appended to the trial's log; its wall seconds."""
    env = {**os.environ, 'OMP_NUM_THREADS': str(threads), 'MKL_NUM_THREADS': str(threads)}
    pid_file = trial.folder.with_name(trial.folder.name + '.pid')
    start = time.perf_counter()
    with trial.log.open('a') as log:
        log.write(f'-- {what}: zeus {" ".join(args)}\n')
        log.flush()
        child = subprocess.Popen([sys.executable, '-m', 'zeus_ros.cli', *args], stdout=log,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
                                 preexec_fn=die_with_parent)
        pid_file.write_text(f'{child.pid}\n')
        try:
            code = child.wait()
        except BaseException:
            child.terminate()
            child.wait()
            raise
        finally:
            pid_file.unlink(missing_ok=True)
    if code != 0:
        raise TrialError(f'{trial.name}: {what} {_ended(code)} (log: {trial.log})')
    return time.perf_counter() - start


def trial_steps(trial: Trial) -> list[tuple[str, list[str], Callable[[float], None]]]:
    """The `zeus` commands the trial still has to run, each with what records it as finished.

    Writes the trial's config.yaml (the training command reads it). A trial with bags or a run
    folder but not trained in its state was cut off: its loop resumes.
    """
    folder, protocol = trial.folder, trial.protocol
    folder.mkdir(parents=True, exist_ok=True)
    state = read_state(folder)
    steps = []
    if not state.trained:
        config = folder / 'config.yaml'
        config.write_text(yaml.safe_dump(trial.config, sort_keys=False))
        (folder / 'protocol.yaml').write_text(yaml.safe_dump(asdict(trial.protocol),
                                                             sort_keys=False))
        resume = (folder / 'bags').is_dir() or (folder / 'run').is_dir()
        steps.append(('training', [
            'loop', '--task', trial.task, '--config', str(config), '--out', str(folder),
            '--rounds', str(protocol.rounds), '--random-steps', str(protocol.random_steps),
            '--steps', str(protocol.steps), '--updates', str(protocol.updates),
            '--noise', str(protocol.noise),
            '--schedule', protocol.schedule or default_schedule(trial.task),
            '--no-eval', '--no-progress', *(['--resume'] if resume else [])],
            partial(mark_trained, folder)))
    for split in trial.splits:
        target = folder / f'eval_{split}'
        if split in state.evaluated:
            continue
        args = ['eval', '--checkpoint', str(folder / 'run' / 'final.pt'), '--task', trial.task,
                '--split', split, '--switch-episodes', '1', '--probe-steps', '0',
                '--seed', str(protocol.eval_seed), '--out', str(target), '--no-progress']
        if protocol.eval_episodes is not None:
            args += ['--episodes', str(protocol.eval_episodes)]
        steps.append((f'evaluation ({split})', args, partial(mark_evaluated, folder, split)))
    return steps


def run_trial(trial: Trial, threads: int = 1) -> float:
    """Run the steps not done yet, each in a subprocess; returns the wall seconds.

    Raises TrialError naming the step that failed and the log. Safe to call again after a
    failure or a kill: it resumes.
    """
    start = time.perf_counter()
    steps = trial_steps(trial)
    with trial.log.open('a') as log:
        stamp = datetime.datetime.now(datetime.UTC).strftime('%Y-%m-%d %H:%M:%S UTC')
        log.write(f'== {stamp} {trial.name} on {socket.gethostname()}, {threads} thread(s)\n')
    for what, args, record in steps:
        record(_run_step(trial, what, args, threads))
    return time.perf_counter() - start
