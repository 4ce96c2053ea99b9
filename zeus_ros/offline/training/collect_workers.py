"""N simulators at once, each writing its own bag (`zeus collect --workers N`, `zeus loop`).

Worker i runs --steps/N steps (the first ones take the remainder) with seed worker_seeds(seed,
N)[i] into bag_{K+i} (bag_K: the next free bag of --out), so the N bags are exactly what N
sequential `zeus collect --seed S_i --steps n_i --append` runs write, and ingest reads the same
arrays from both (tested). Workers are processes, or Ray tasks with --ray (one CPU each; on a
cluster, RAY_ADDRESS, every node writes into --out, which must be a shared folder).
The seeds come from numpy's SeedSequence(seed).spawn(N): independent streams, reproducible from
the run seed, never the neighbouring seeds another run uses; a single worker keeps the run
seed.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
import multiprocessing
from pathlib import Path
from typing import Any

import numpy as np

from zeus_ros.bags.kinds import BagLabel
from zeus_ros.offline.rollout import CollectStats

__all__ = ['CollectJob', 'collect_bag', 'portable_task', 'run_workers', 'split_steps',
           'worker_seeds']


@dataclass(frozen=True)
class CollectJob:
    """One collection into one bag: what `zeus collect` (or a loop round) runs."""

    task: str
    schedule: dict[str, Any]
    bag: Path
    steps: int
    seed: int
    checkpoint: Path | None = None
    noise: float = 0.0
    stochastic: bool = False
    context_lag: int = 0
    pixels: bool = False
    storage: str = 'mcap'
    progress: bool = False
    schedule_start: tuple[int, int] = (0, 0)
    """The schedule's (step, episode) at the first step: where earlier collections stopped."""


def portable_task(name: str) -> str:
    """A task a fresh process can build: a file-declared task by its file, else its name."""
    from sim_bridge.registry import declared_task

    declared = declared_task(name)
    return str(declared.source) if declared is not None else name


def collected_label(task: str, checkpoint: Path | str | None) -> BagLabel:
    """The label of a bag that `zeus collect` or a loop round writes (bags/kinds.py)."""
    from sim_bridge.registry import declared_task

    declared = declared_task(task)
    name = declared.name if declared is not None else task
    return BagLabel('collected', task=name, checkpoint=str(checkpoint or ''))


def worker_seeds(seed: int, workers: int) -> list[int]:
    """The seed of each worker: the run seed for one worker, else SeedSequence children."""
    if workers == 1:
        return [seed]
    return [int(child.generate_state(1)[0]) for child in np.random.SeedSequence(seed).spawn(
        workers)]


def split_steps(steps: int, workers: int) -> list[int]:
    """`steps` over `workers` as evenly as possible (the first ones take the remainder)."""
    return [steps // workers + (1 if i < steps % workers else 0) for i in range(workers)]


def collect_bag(job: CollectJob) -> CollectStats:
    """Build the task, schedule and policy of `job` and write its bag (no ROS)."""
    from sim_bridge.env import ScheduledEnv
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config
    from zeus_ros.bags.writer import StepBagWriter
    from zeus_ros.offline.rollout import (
        AgentPolicy,
        CollectDiskFull,
        collect,
        disk_full_line,
        random_policy,
    )

    task = make_task(job.task, seed=job.seed)
    try:
        env = ScheduledEnv(task, schedule_from_config(job.schedule, task, job.seed),
                           job.schedule_start)
        policy = random_policy(task, job.seed)
        if job.checkpoint is not None:
            from zeus_ros.learning.inference import InferenceAgent

            agent = InferenceAgent.from_checkpoint(job.checkpoint, expect_task=task.name,
                                                   reuse_features=True)  # as the nodes do
            policy = AgentPolicy(agent, noise=0.0 if job.stochastic else job.noise,
                                 seed=job.seed, stochastic=job.stochastic,
                                 context_lag=job.context_lag)
        job.bag.parent.mkdir(parents=True, exist_ok=True)
        writer: StepBagWriter | None = None
        try:
            with StepBagWriter(job.bag, storage=job.storage, pixels=job.pixels,
                               label=collected_label(job.task, job.checkpoint)) as writer:
                return collect(env, task, policy, writer, job.steps, progress=job.progress)
        except Exception as error:  # a full disk: one line for the parent, not a traceback
            line = disk_full_line(error, job.bag, writer, job.steps)
            if line is None:
                raise
            raise CollectDiskFull(line) from None
    finally:
        task.close()


def _worker(job: CollectJob) -> CollectStats:
    """A worker process or Ray task: one torch thread, as `zeus collect` and the nodes use."""
    import torch

    torch.set_num_threads(1)
    return collect_bag(job)


def run_workers(template: CollectJob, workers: int, *, use_ray: bool = False,
                log: Any = print) -> list[CollectStats]:
    """Split `template` over `workers` bags (bag_K, bag_K+1, ...) and collect them at once."""
    first = int(template.bag.name.rsplit('_', 1)[1])
    template = replace(template, task=portable_task(template.task))
    jobs = [replace(template, bag=template.bag.with_name(f'bag_{first + i:03d}'), steps=steps,
                    seed=seed, progress=False)
            for i, (steps, seed) in enumerate(zip(split_steps(template.steps, workers),
                                                  worker_seeds(template.seed, workers),
                                                  strict=True))]
    for i, job in enumerate(jobs):
        log(f'worker {i}: {job.steps} steps, seed {job.seed} -> {job.bag}')
    if use_ray:
        import ray

        from zeus_ros.offline.training.ray_runtime import start_ray

        started = start_ray()
        try:
            remote = ray.remote(num_cpus=1, max_retries=0)(_worker)
            return ray.get([remote.remote(job) for job in jobs])
        finally:
            if started:
                ray.shutdown()
    stats: dict[int, CollectStats] = {}
    context = multiprocessing.get_context('spawn')
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = {pool.submit(_worker, job): i for i, job in enumerate(jobs)}
        for future in as_completed(futures):
            stats[futures[future]] = future.result()
            log(f'worker {futures[future]}: done, {stats[futures[future]].steps} steps')
    return [stats[i] for i in range(workers)]
