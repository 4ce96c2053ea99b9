"""`zeus collect`: run a scheduled task in-process (no ROS) and write bags like the recorder.

The rollout itself is zeus_ros/offline/rollout.py (`collect`, the policies) and, with
--workers, zeus_ros/offline/training/collect_workers.py; this module reads the command line
and checks it before those (numpy, bags, MuJoCo) are imported: --help answers at once (issue 52).
"""

from __future__ import annotations

import argparse
from pathlib import Path
import shutil
import signal
import sys
import time
from typing import TYPE_CHECKING, Any

from zeus_ros.cli_args import TASK_HELP, ZeusArgumentParser, at_least, seed_arg, task_name
from zeus_ros.offline.schedule_text import SCHEDULE_HELP

if TYPE_CHECKING:
    from zeus_ros.bags.writer import StepBagWriter

__all__ = ['main']

def _build_parser() -> argparse.ArgumentParser:
    parser = ZeusArgumentParser(
        prog='zeus collect',
        description='Run a task with a context schedule in-process and write a rosbag2 bag '
        'with the topics and stamps the live nodes publish (no ROS needed).',
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=SCHEDULE_HELP,
    )
    parser.add_argument('--task', '--task-file', required=True, type=task_name, help=TASK_HELP)
    parser.add_argument('--schedule', default='constant', help='see below (default: constant)')
    parser.add_argument('--steps', type=at_least(1), required=True, help='control steps to record')
    parser.add_argument('--seed', type=seed_arg, default=0,
                        help='seeds task, schedule and policy')
    parser.add_argument('--out', type=Path, required=True, help='directory for the bag(s)')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap')
    parser.add_argument('--pixels', action='store_true', help='also record 84x84 rgb8 frames')
    parser.add_argument('--checkpoint', type=Path,
                        help='act with this agent, not at random')
    parser.add_argument('--noise', type=at_least(0.0, float), default=0.0,
                        help='Gaussian exploration noise for --checkpoint, as a fraction of '
                        'half the action range (actions are clipped to the bounds)')
    parser.add_argument('--context-lag', type=at_least(0), default=0,
                        help="act on step k with the context of step k - L, as the policy "
                        "node's context_lag parameter does, within its limit (default: 0)")
    parser.add_argument('--append', action='store_true',
                        help='add a new bag next to the bags already in --out')
    parser.add_argument('--no-progress', action='store_true', help='hide the progress bar')
    parser.add_argument('--workers', type=at_least(1), default=1,
                        help='simulators at once, each writing its own bag of --steps/N steps '
                        'with a seed derived from --seed (default: 1)')
    parser.add_argument('--ray', action='store_true',
                        help='run the workers as Ray tasks (RAY_ADDRESS: on that cluster, '
                        '--out shared), not as local processes')
    parser.must_exist('--checkpoint')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus collect`; returns the process exit code."""
    args = _build_parser().parse_args(argv)
    if args.steps < 1:
        print(f'zeus collect: --steps must be >= 1, got {args.steps}', file=sys.stderr)
        return 2
    if args.context_lag:
        from zeus_ros.learning.inference import MAX_CONTEXT_LAG  # torch: only with a lag

        if not 0 <= args.context_lag <= MAX_CONTEXT_LAG:
            print(f'zeus collect: --context-lag must be between 0 and {MAX_CONTEXT_LAG} (the '
                  f"policy node's limit), got {args.context_lag}", file=sys.stderr)
            return 2
    if not 1 <= args.workers <= args.steps:
        print(f'zeus collect: --workers must be between 1 and --steps ({args.steps}), got '
              f'{args.workers}', file=sys.stderr)
        return 2
    from zeus_ros.bags.writer import StepBagWriter
    from zeus_ros.offline.rollout import (
        AgentPolicy,
        CollectDiskFull,
        collect,
        disk_full_line,
        next_bag_path,
        parse_schedule,
        random_policy,
    )

    try:
        schedule_config = parse_schedule(args.schedule)
        bag = next_bag_path(args.out, append=args.append)
    except (ValueError, FileExistsError) as exc:
        print(f'zeus collect: {exc}', file=sys.stderr)
        return 2
    from sim_bridge.env import ScheduledEnv
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config
    from zeus_ros.learning.errors import CheckpointError
    from zeus_ros.offline.training.collect_workers import collected_label

    try:
        task = make_task(args.task, seed=args.seed)
    except (KeyError, ValueError) as exc:
        print(f'zeus collect: --task {args.task}: {exc}', file=sys.stderr)
        return 2
    try:
        schedule = schedule_from_config(schedule_config, task, args.seed)
    except (KeyError, TypeError, ValueError) as exc:
        task.close()
        print(f'zeus collect: --schedule {args.schedule}: {exc}', file=sys.stderr)
        return 2
    env = ScheduledEnv(task, schedule)
    policy = random_policy(task, args.seed)
    if args.checkpoint is not None:
        import torch

        from zeus_ros.learning.inference import InferenceAgent

        # One thread, as the policy and estimator nodes run: the same float results (a live
        # recording and a collection of the same schedule ingest to identical arrays).
        torch.set_num_threads(1)
        try:
            agent = InferenceAgent.from_checkpoint(args.checkpoint, expect_task=task.name,
                                                   reuse_features=True)  # as the nodes do
        except CheckpointError as exc:
            task.close()
            print(f'zeus collect: --checkpoint: {exc}', file=sys.stderr)
            return 2
        if agent.obs_kind == 'pixels' and not args.pixels:
            task.close()
            print(f'zeus collect: {args.checkpoint} is a pixel agent; add --pixels',
                  file=sys.stderr)
            return 2
        policy = AgentPolicy(agent, noise=args.noise, seed=args.seed,
                             context_lag=args.context_lag)
    if args.workers > 1 or args.ray:  # checked above, collected by the workers
        task.close()
        before = set(args.out.glob('bag_*'))
        try:
            return main_workers(args, schedule_config, bag)
        except CollectDiskFull as full:  # every bag of this run goes: none is whole
            for new in set(args.out.glob('bag_*')) - before:
                shutil.rmtree(new, ignore_errors=True)
            print(f'zeus collect: {full}; so is every other bag of this run', file=sys.stderr)
            return 2
    # SIGTERM ends the run like Ctrl-C, so the bag is still finalized and readable.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    writer: StepBagWriter | None = None
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        with StepBagWriter(bag, storage=args.storage, pixels=args.pixels,
                           label=collected_label(task.name, args.checkpoint)) as writer:
            stats = collect(env, task, policy, writer, args.steps, progress=not args.no_progress)
    except KeyboardInterrupt:
        print(f'zeus collect: interrupted; the steps written so far are in {bag}',
              file=sys.stderr)
        return 130
    except Exception as error:  # a full disk is one line; anything else is a bug: traceback
        line = disk_full_line(error, bag, writer, args.steps)
        if line is None:
            raise
        print(f'zeus collect: {line}', file=sys.stderr)
        return 2
    finally:
        task.close()
    print(f'wrote {stats.steps} steps ({stats.episodes} episode starts) to {stats.bag} in '
          f'{stats.seconds:.1f} s ({stats.steps_per_s:.0f} steps/s)')
    return 0



def main_workers(args: Any, schedule: dict[str, Any], bag: Path) -> int:
    """`zeus collect --workers N` after main checked every flag; the exit code."""
    from zeus_ros.offline.training.collect_workers import CollectJob, run_workers

    template = CollectJob(args.task, schedule, bag, args.steps, args.seed,
                          checkpoint=args.checkpoint, noise=args.noise, pixels=args.pixels,
                          storage=args.storage, context_lag=args.context_lag)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    args.out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    try:
        stats = run_workers(template, args.workers, use_ray=args.ray)
    except KeyboardInterrupt:
        print(f'zeus collect: interrupted; the steps written so far are in {args.out}',
              file=sys.stderr)
        return 130
    seconds = time.perf_counter() - start  # with the workers' start-up: what a user waits
    total = sum(s.steps for s in stats)
    print(f'wrote {total} steps ({sum(s.episodes for s in stats)} episode starts) to '
          f'{len(stats)} bags {stats[0].bag.name}..{stats[-1].bag.name} in {args.out} in '
          f'{seconds:.1f} s ({total / max(seconds, 1e-9):.0f} steps/s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
