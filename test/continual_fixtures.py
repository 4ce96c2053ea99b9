"""Checkpoints and recordings for the continual-deployment tests (real MuJoCo data).

A swap needs a candidate that is really better within a test's budget. Short fine-tunes of a
good policy only degrade it (the gate refuses them, as it should), so the swap tests deploy a
weak policy with a competent critic: the archive's resumable Cheetah-Run-v0 checkpoint
(35k updates, critics included) with its actor re-initialised. A few hundred actor updates
against that critic earn clearly more, and the gate measures it.
"""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FULL_RUN_V0 = REPO / 'checkpoints' / 'cheetah_run_v0_zeus_state.pt'
"""The only resumable (critics + optimizers) checkpoint in the repository."""
WEAK_TASK = 'Cheetah-Run-v0'


def weak_checkpoint(path: Path, seed: int = 0) -> Path:
    """FULL_RUN_V0 with a freshly initialised actor: weak, and quickly improvable."""
    import torch

    from zeus_ros.learning.checkpoint import load_checkpoint, save_checkpoint
    from zeus_ros.learning.utils import weight_init

    loaded = load_checkpoint(FULL_RUN_V0)
    torch.manual_seed(seed)
    loaded.agent.modules['actor'].apply(weight_init)
    return save_checkpoint(path, loaded.agent, step=loaded.step, extra={'weak_from': 'test'})


def record(folder: Path, task: str, values: list[float], checkpoint: Path, splits: int,
           steps: int, every: int = 100, seed: int = 10, one_run: bool = False) -> list[Path]:
    """`splits` closed bags of `steps` steps each, as the recorder's splits of one run.

    Each split is a collection of its own (steps, segments and bag times start anew), unless
    `one_run`: then one simulator runs on across the splits, as under the recorder (step and
    segment indices go on, bag times are one wall clock), each split starting an episode.
    """
    from sim_bridge.families import family
    from zeus_ros.offline.training.collect_workers import CollectJob, collect_bag

    name = family(task).specs[0].name
    schedule = {'kind': 'switch', 'every': every, 'values': [{name: v} for v in values]}
    bags = [folder / f'{folder.name}_{i:03d}' for i in range(splits)]
    if one_run:
        return _record_one_run(bags, task, schedule, checkpoint, steps, seed)
    for i, bag in enumerate(bags):
        collect_bag(CollectJob(task, schedule, bag, steps, seed + i, checkpoint=checkpoint,
                               noise=0.2))
    return bags


def _record_one_run(bags: list[Path], task_name: str, schedule: dict, checkpoint: Path,
                    steps: int, seed: int) -> list[Path]:
    import time

    from sim_bridge.env import ScheduledEnv
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config
    from zeus_ros.bags.writer import StepBagWriter
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.rollout import AgentPolicy, collect

    task = make_task(task_name, seed=seed)
    try:
        env = ScheduledEnv(task, schedule_from_config(schedule, task, seed))
        agent = InferenceAgent.from_checkpoint(checkpoint, expect_task=task.name,
                                               reuse_features=True)
        policy = AgentPolicy(agent, noise=0.2, seed=seed)
        start_ns = time.time_ns()
        for bag in bags:
            bag.parent.mkdir(parents=True, exist_ok=True)
            with StepBagWriter(bag, pixels=False, start_ns=start_ns) as writer:
                collect(env, task, policy, writer, steps, progress=False)
    finally:
        task.close()
    return bags
