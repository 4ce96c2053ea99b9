"""`zeus eval` on many checkpoints: every split of each, in parallel, then the tables over seeds.

    zeus eval --checkpoint checkpoints/comparison --split all --out out/tables --jobs 2

Each checkpoint is evaluated into <out>/<group>/<method>_s<seed>/eval_<split>/, where the group
names task and update budget (cheetah_run_v0_10k). Finished parts (recorded in
<method>_s<seed>/state.json, offline/runs.py) are skipped, so an interrupted run resumes.
report.write_report then writes per-group summary.csv / runs.csv / table.md / returns.png, and
<out>/tables.md holds every group's table.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
import multiprocessing
from pathlib import Path
import time
from typing import Any

from tqdm import tqdm

from zeus_ros.offline.runs import mark_evaluated, read_state

__all__ = ['EvalJob', 'evaluate_many', 'find_checkpoints', 'group_name']


def group_name(task: str, updates: int) -> str:
    """Cheetah-Run-v0 after 10,000 updates -> cheetah_run_v0_10k: one table per task and budget."""
    budget = f'{updates // 1000}k' if updates % 1000 == 0 else str(updates)
    return f"{task.lower().replace('-', '_')}_{budget}"


def find_checkpoints(paths: Iterable[Path]) -> list[Path]:
    """Files as given, folders searched recursively for *.pt; sorted, without repeats."""
    found: list[Path] = []
    for path in paths:
        if path.is_dir():
            found += sorted(path.rglob('*.pt'))
        elif path.is_file():
            found.append(path)
        else:
            raise FileNotFoundError(f'--checkpoint {path}: no such file or folder')
    unique = list(dict.fromkeys(p.resolve() for p in found))
    if not unique:
        raise FileNotFoundError('--checkpoint: no *.pt files found in '
                                + ', '.join(str(p) for p in paths))
    return unique


@dataclass(frozen=True)
class EvalJob:
    """One (checkpoint, split) evaluation and where its results go."""

    checkpoint: Path
    task: str
    split: str
    out: Path


def _identify(path: Path, expect_task: str | None) -> tuple[str, str, int, int]:
    """(task, method, seed, updates) stored in a checkpoint."""
    from zeus_ros.learning.checkpoint import load_checkpoint

    loaded = load_checkpoint(path, load_optimizers=False, expect_task=expect_task)
    return loaded.spec.task, loaded.config.method, int(loaded.config.seed), loaded.step


def plan(checkpoints: Sequence[Path], out: Path, splits: Sequence[str] | None,
         force: bool = False, expect_task: str | None = None
         ) -> tuple[list[EvalJob], list[str]]:
    """Jobs still to run, and the group folders they belong to (in order of appearance)."""
    from sim_bridge.families import load_preset

    owners: dict[Path, Path] = {}
    jobs, tasks = [], []
    for path in checkpoints:
        task, method, seed, updates = _identify(path, expect_task)
        group = group_name(task, updates)
        run = out / group / f'{method}_s{seed}'
        if run in owners and owners[run].parent == path.parent:
            print(f'zeus eval: skipping {path}: same run and update as {owners[run]}')
            continue
        if run in owners:
            raise ValueError(f'{owners[run]} and {path} are both {task} {method} seed {seed} '
                             f'after {updates} updates; evaluate them into different --out')
        owners[run] = path
        if group not in tasks:
            tasks.append(group)
        wanted = splits or [s for s in ('train', 'interpolation', 'extrapolation')
                            if _has_split(load_preset, task, s)]
        finished = read_state(run).evaluated
        for split in wanted:
            if force or split not in finished:
                jobs.append(EvalJob(path, task, split, run / f'eval_{split}'))
    return jobs, tasks


def _has_split(load_preset: Any, task: str, split: str) -> bool:
    try:
        return bool(load_preset(task, split))
    except (KeyError, ValueError):
        return False


def _run_job(job: EvalJob, protocol: dict[str, Any]) -> tuple[EvalJob, float]:
    """Worker: one evaluation on one torch thread; records it in the run's state.json."""
    import torch

    from zeus_ros.offline.evaluation.evaluate import evaluate

    torch.set_num_threads(1)
    start = time.perf_counter()
    evaluate(job.checkpoint, split=job.split, task=job.task, out=job.out, progress=False,
             **protocol)
    seconds = time.perf_counter() - start
    mark_evaluated(job.out.parent, job.split, seconds)
    return job, seconds


def evaluate_many(checkpoints: Sequence[Path], out: Path, *, splits: Sequence[str] | None,
                  jobs: int = 1, force: bool = False, progress: bool = True,
                  expect_task: str | None = None, **protocol: Any
                  ) -> dict[str, list[dict[str, Any]]]:
    """Evaluate every checkpoint on `splits` (None: all its task defines); tables per task."""
    from zeus_ros.offline.evaluation.report import markdown_table, write_report

    todo, tasks = plan(checkpoints, out, splits, force, expect_task)
    print(f'zeus eval: {len(checkpoints)} checkpoint(s), {len(todo)} evaluation(s) to run '
          f'({jobs} at a time) into {out}')
    bar = tqdm(total=len(todo), desc='evaluations', unit='eval', disable=not progress)
    if jobs <= 1:
        for job in todo:
            _run_job(job, protocol)
            bar.update()
    else:
        context = multiprocessing.get_context('spawn')
        with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
            futures = [pool.submit(_run_job, job, protocol) for job in todo]
            for future in as_completed(futures):
                future.result()
                bar.update()
    bar.close()
    tables: dict[str, list[dict[str, Any]]] = {}
    sections = []
    for name in tasks:
        folder = out / name
        tables[name] = write_report(folder, folder, title=name)
        sections.append(f'## {name}\n\n{markdown_table(tables[name])}\n')
    (out / 'tables.md').write_text('\n'.join(sections))
    return tables
