r"""`zeus sweep`: tasks x methods x seeds x --set overrides, each trial a Ray task.

    zeus sweep --tasks Cheetah-Run-v0 Walker-Walk-v0 --methods zeus no_context --seeds 0-4 \\
        --set alpha_psi=0.5,1.0 --out runs/sweep

Each trial is the record -> retrain loop of experiments/run_one.sh (`zeus loop`, then `zeus eval`
on every split the task defines; trial.py) run as one Ray task holding --cpus-per-trial CPUs
(and a GPU for pixel configs when the cluster has one); torch uses that many threads, so all
cores are used and none oversubscribed. Finished trials are skipped, so a rerun resumes; a failed
trial is retried once (resuming), then reported with its log. At the end the `zeus report`
tables of every group are written (<group>/table.md, ..., and <out>/tables.md).
Local Ray is loopback-only (ray_runtime.py); `--address` or RAY_ADDRESS joins a cluster, whose
workers must see --out at the same path (docs/sweep.md).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
import csv
from dataclasses import dataclass, field
import itertools
from pathlib import Path
import time
from typing import Any

from sim_bridge.presets import SPLITS
from zeus_ros.offline.training.collect_workers import portable_task
from zeus_ros.offline.training.trial import (
    LoopProtocol,
    Trial,
    TrialError,
    recorded_differences,
    run_trial,
    trial_done,
)

__all__ = ['SweepError', 'SweepResult', 'default_config', 'group_name', 'parse_seeds',
           'parse_sets', 'plan', 'run_sweep', 'write_status', 'write_tables']


class SweepError(ValueError):
    """A bad grid or flag, found before any trial starts."""


def parse_seeds(text: str) -> list[int]:
    """'0-4' -> 0..4; '0,3,7' and '0-2,9' too."""
    seeds: list[int] = []
    for part in (p.strip() for p in text.split(',')):
        first, dash, last = part.partition('-')
        try:
            if not dash:
                seeds.append(int(part))
                continue
            low, high = int(first), int(last)
            if high < low:
                raise ValueError
            seeds += range(low, high + 1)
        except ValueError:
            raise SweepError(f'--seeds {text}: {part!r} is not a seed or a range FIRST-LAST; '
                             'write e.g. 0-4 or 0,2,5') from None
    return list(dict.fromkeys(seeds))


def parse_sets(items: Sequence[str]) -> list[dict[str, Any]]:
    """['k=a,b', 'j=c'] -> [{k: a, j: c}, {k: b, j: c}]: the product of every key's values.

    Parsed by config_sets (the one --set parser of train, loop and sweep); method and seed are
    axes of their own here.
    """
    from zeus_ros.config_sets import parse_set_grid

    for item in items:
        key = item.partition('=')[0].strip()
        if key in ('method', 'seed'):
            raise SweepError(f'--set {item}: {key} is a grid axis of its own: use --{key}s')
    axes = parse_set_grid(items)
    keys = list(axes)
    combos = itertools.product(*axes.values())
    return [dict(zip(keys, combo, strict=True)) for combo in combos] or [{}]


def group_name(task: str, overrides: dict[str, Any]) -> str:
    """cheetah_run_v0, or cheetah_run_v0__alpha_psi=0.5 with overrides: one report per group."""
    slug = task.lower().replace('-', '_')
    return slug + ''.join(f'__{key}={value}' for key, value in overrides.items())


def _task_splits(task: str, wanted: Sequence[str] | None) -> tuple[str, ...]:
    from sim_bridge.families import load_preset
    from sim_bridge.registry import task_class

    try:
        task_class(task)
    except ValueError as error:
        raise SweepError(f'--tasks: {error}') from None

    def defined(split: str) -> bool:
        try:
            return bool(load_preset(task, split))
        except (KeyError, ValueError):
            return False

    if wanted is None:
        return tuple(s for s in SPLITS if defined(s))
    missing = [s for s in wanted if not defined(s)]
    if missing:
        raise SweepError(f'--eval-splits: {task} defines no {", ".join(missing)} split '
                         f'(params/tasks/{task}.yaml); leave it out or pick others')
    return tuple(wanted)


def plan(tasks: Sequence[str], methods: Sequence[str], seeds: Sequence[int],
         sets: Sequence[dict[str, Any]], base: Any, out: Path, protocol: LoopProtocol,
         splits: Sequence[str] | None = None, evaluate: bool = True) -> list[Trial]:
    """Every trial of the grid, each config validated now (not hours later on a worker)."""
    from zeus_ros.learning.config import config_from_dict
    from zeus_ros.learning.errors import ConfigError

    trials = []
    for task in tasks:
        task_splits = _task_splits(task, splits) if evaluate else ()
        for overrides, method, seed in itertools.product(sets, methods, seeds):
            group = group_name(task, overrides)
            values = {**base.to_dict(), **overrides, 'method': method, 'seed': seed}
            try:
                config = config_from_dict(values, source=f'--set {overrides}' if overrides
                                          else f'--methods {method}')
            except ConfigError as error:
                raise SweepError(str(error)) from None
            trials.append(Trial(task=portable_task(task), method=method, seed=seed, group=group,
                                folder=out / group / f'{method}_s{seed}',
                                config=config.to_dict(), splits=task_splits,
                                protocol=protocol))
    return trials


@dataclass
class SweepResult:
    """What a sweep did: trial names per outcome, and why each failed one failed."""

    done: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    attempts: dict[str, int] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)


def _reason(error: BaseException) -> str:
    """One line: a TrialError's own message, else the Ray error's type and first line."""
    cause = getattr(error, 'cause', None) or error
    if isinstance(cause, TrialError):
        return str(cause)
    text = str(cause).strip().splitlines()
    return f'{type(cause).__name__}: {text[-1] if text else ""}'


def _gpus(trial: Trial, wanted: float | None, cluster_gpus: float) -> float:
    """--gpus-per-trial, else one GPU for a pixel config when the cluster has any."""
    if wanted is not None:
        return wanted
    return 1.0 if trial.config.get('obs_kind') == 'pixels' and cluster_gpus >= 1 else 0.0


def run_sweep(trials: Sequence[Trial], *, address: str | None = None,
              num_cpus: int | None = None, cpus_per_trial: int = 1,
              gpus_per_trial: float | None = None, retries: int = 1,
              log: Any = print, on_start: Callable[[], Any] | None = None) -> SweepResult:
    """Run the unfinished trials as Ray tasks; retry each failure `retries` times.

    `on_start` is called once Ray is up (before any trial is submitted).
    """
    import ray

    from zeus_ros.offline.training.ray_runtime import start_ray

    result = SweepResult()
    for trial in trials:
        differences = recorded_differences(trial)
        if differences:
            raise SweepError(f'{trial.folder} was run with other settings ('
                             f'{"; ".join(differences[:3])}); use the same flags to resume it, '
                             'or another --out')
    todo = [t for t in trials if not trial_done(t)]
    result.skipped = [t.name for t in trials if trial_done(t)]
    log(f'sweep: {len(trials)} trial(s): {len(result.skipped)} finished before (skipped), '
        f'{len(todo)} to run')
    if not todo:
        return result
    started_here = start_ray(address, num_cpus)
    pending: dict[Any, tuple[Trial, int]] = {}
    try:
        if on_start is not None:
            on_start()
        resources = ray.cluster_resources()
        if resources.get('CPU', 0) < cpus_per_trial:
            raise SweepError(f'--cpus-per-trial {cpus_per_trial}: the Ray cluster has only '
                             f'{resources.get("CPU", 0):g} CPU(s)')
        tracker = ray.remote(num_cpus=0)(_StartedNames).remote()
        remote = ray.remote(_ray_trial)

        def submit(trial: Trial, attempt: int) -> None:
            gpus = _gpus(trial, gpus_per_trial, resources.get('GPU', 0))
            ref = remote.options(num_cpus=cpus_per_trial, num_gpus=gpus, max_retries=0,
                                 name=f'trial {trial.name}').remote(
                trial, cpus_per_trial, tracker, f'{trial.name}#{attempt}')
            pending[ref] = (trial, attempt)
            result.attempts[trial.name] = attempt

        for trial in todo:
            submit(trial, 1)
        shown = None
        begin = time.monotonic()
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=2.0)
            for ref in ready:
                trial, attempt = pending.pop(ref)
                try:
                    result.seconds[trial.name] = ray.get(ref)
                    result.done.append(trial.name)
                except Exception as error:  # TrialError from the task, or a Ray failure
                    why = _reason(error)
                    if attempt <= retries:
                        log(f'sweep: {trial.name} failed ({why}); retrying (attempt '
                            f'{attempt + 1})')
                        submit(trial, attempt + 1)
                    else:
                        log(f'sweep: {trial.name} FAILED after {attempt} attempt(s): {why}')
                        result.failed[trial.name] = why
            attempts = {f'{t.name}#{a}' for t, a in pending.values()}
            running = len(attempts & ray.get(tracker.names.remote()))
            line = (f'{len(result.done) + len(result.skipped)}/{len(trials)} done, {running} '
                    f'running, {len(result.failed)} failed')
            if line != shown:
                log(f'sweep: {line} ({time.monotonic() - begin:.0f} s)')
                shown = line
    except KeyboardInterrupt:
        for ref in pending:  # a cluster would run them on without us
            ray.cancel(ref, force=True)
        raise
    finally:
        if started_here:
            ray.shutdown()
    return result


def _ray_trial(trial: Trial, threads: int, tracker: Any, attempt: str) -> float:
    """The Ray task: say this attempt started, then run the trial with `threads` threads."""
    tracker.add.remote(attempt)
    return run_trial(trial, threads)


class _StartedNames:
    """Names of the trials that started: Ray tells which tasks run only via its dashboard."""

    def __init__(self) -> None:
        self._names: set[str] = set()

    def add(self, name: str) -> None:
        self._names.add(name)

    def names(self) -> set[str]:
        return self._names


def write_tables(trials: Iterable[Trial], out: Path) -> str:
    """`zeus report` of every group with a finished evaluation; <out>/tables.md; its text."""
    from zeus_ros.offline.evaluation.report import markdown_table, write_report

    sections = []
    for group in dict.fromkeys(t.group for t in trials):
        try:
            rows = write_report(out / group, out / group, title=group)
        except FileNotFoundError:
            continue
        sections.append(f'## {group}\n\n{markdown_table(rows)}\n')
    text = '\n'.join(sections)
    if text:
        (out / 'tables.md').write_text(text)
    return text


def write_status(trials: Sequence[Trial], result: SweepResult, out: Path) -> Path:
    """<out>/sweep.csv: every trial's status, attempts, seconds and log."""
    path = out / 'sweep.csv'
    with path.open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(['trial', 'status', 'attempts', 'seconds', 'log', 'error'])
        for trial in trials:
            status = ('skipped' if trial.name in result.skipped else 'failed'
                      if trial.name in result.failed else 'done')
            seconds = result.seconds.get(trial.name)
            writer.writerow([trial.name, status, result.attempts.get(trial.name, 0),
                             '' if seconds is None else f'{seconds:.1f}', trial.log,
                             result.failed.get(trial.name, '')])
    return path


def default_config() -> Path:
    """The base training config of a sweep that names none: params/train/state_cpu.yaml."""
    from sim_bridge.presets import find_params_dir

    return find_params_dir() / 'train' / 'state_cpu.yaml'
