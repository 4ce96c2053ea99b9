"""`zeus eval`: the command line of checkpoint evaluation.

The library is zeus_ros/offline/evaluation/evaluate.py (`evaluate(checkpoint, split=...)` for
one checkpoint) and eval_batch.py (`evaluate_many` for several, then the tables over seeds);
this module only reads the arguments, calls one of them and prints what came back. The
libraries (torch, MuJoCo) are imported once the arguments are parsed and the checkpoints found,
so --help and a wrong path answer at once (issue 52).
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

from sim_bridge.presets import SPLITS
from zeus_ros.cli_args import (
    EXPECT_SHA256_HELP,
    TASK_HELP,
    ZeusArgumentParser,
    at_least,
    seed_arg,
    sha256_arg,
    task_name,
)

__all__ = ['main']


def _build_parser() -> argparse.ArgumentParser:
    parser = ZeusArgumentParser(
        prog='zeus eval', description='Evaluate a checkpoint in-process on a context split.')
    parser.add_argument('--checkpoint', type=Path, nargs='+', required=True,
                        help='checkpoint file(s) or folder(s) of them; several (or a folder, or '
                        '--split all) evaluate each into OUT/<task>/<method>_s<seed>/ and '
                        'write the tables over seeds (OUT/tables.md)')
    parser.add_argument('--expect-sha256', type=sha256_arg, metavar='SHA256',
                        help=f'{EXPECT_SHA256_HELP}; one checkpoint only')
    parser.add_argument('--task', '--task-file', type=task_name,
                        help=f'expected task (error if the checkpoint has another); {TASK_HELP}')
    parser.add_argument('--split', choices=(*SPLITS, 'all'), default='train',
                        help="context split; 'all': every split the task's preset defines")
    parser.add_argument('--values',
                        help="any values of the task's context parameters instead of a split, "
                        "e.g. '0.5,0.8,1.3' (one parameter) or 'x=0.1:y=0.2,x=0.3:y=0.1'; "
                        "outputs are labelled split 'custom'")
    parser.add_argument('--episodes', type=at_least(1), default=3,
                        help='episodes per context value (each from other initial states)')
    parser.add_argument('--switch-every', type=at_least(1),
                        help='steps between unannounced context switches (switching run; '
                        'default 100, or a quarter episode for shorter episodes)')
    parser.add_argument('--switch-episodes', type=at_least(0), default=1,
                        help='episodes of the switching run')
    parser.add_argument('--probe-steps', type=at_least(0), default=4000,
                        help='random-policy steps for the identifiability probe (0: skip)')
    parser.add_argument('--seed', type=seed_arg, default=100)
    parser.add_argument('--out', type=Path,
                        help='output folder (default: eval_<split>/ next to the checkpoint); '
                        'zeus export and zeus report find the results in any folder below the '
                        "checkpoint's (eval.json names the checkpoint evaluated)")
    parser.add_argument('--jobs', type=at_least(1), default=1,
                        help='evaluations in parallel (several checkpoints)')
    parser.add_argument('--force', action='store_true',
                        help='re-run evaluations that already finished (several checkpoints)')
    parser.add_argument('--threads', type=at_least(1), default=1,
                        help='torch CPU threads (default 1: these networks act on one '
                        'observation at a time, where more threads only wait on each other, '
                        'several times slower on a busy machine; the nodes and --jobs use 1 '
                        'too, so the numbers agree)')
    parser.add_argument('--no-progress', action='store_true')
    parser.must_exist('--checkpoint')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus eval`; returns the process exit code."""
    from zeus_ros.learning.errors import CheckpointError

    args = _build_parser().parse_args(argv)
    for flag in ('episodes', 'switch_every', 'switch_episodes', 'jobs'):
        if getattr(args, flag) is not None and getattr(args, flag) < 1:
            print(f'zeus eval: --{flag.replace("_", "-")} must be >= 1', file=sys.stderr)
            return 2
    if args.values is not None and args.split == 'all':
        print('zeus eval: --values replaces the split: drop --split all', file=sys.stderr)
        return 2
    many = len(args.checkpoint) > 1 or args.checkpoint[0].is_dir() or args.split == 'all'
    if many and args.expect_sha256:
        print('zeus eval: --expect-sha256 pins one checkpoint file (one split): pin several '
              'with a sidecar FILE.sha256 each', file=sys.stderr)
        return 2
    import torch

    from zeus_ros.offline.evaluation.evaluate import evaluate, parse_values
    from zeus_ros.offline.evaluation.metrics import format_table

    torch.set_num_threads(args.threads)
    if many:
        return _main_many(args)
    try:
        values = None
        if args.values is not None:
            from zeus_ros.learning.inference import InferenceAgent

            names = InferenceAgent.from_checkpoint(
                args.checkpoint[0], expect_task=args.task,
                expect_sha256=args.expect_sha256).context_names
            values = parse_values(args.values, names)
        result = evaluate(args.checkpoint[0], split='custom' if values else args.split,
                          task=args.task, values=values, expect_sha256=args.expect_sha256,
                          episodes=args.episodes, switch_every=args.switch_every,
                          switch_episodes=args.switch_episodes, probe_steps=args.probe_steps,
                          seed=args.seed, out=args.out, progress=not args.no_progress)
    except (CheckpointError, ValueError, FileNotFoundError) as error:
        print(f'zeus eval: {error}', file=sys.stderr)
        return 2
    per_value = result['per_value']
    table = [{'context': label, **{policy: returns[i] for policy, returns in per_value.items()}}
             for i, label in enumerate(result['values'])]
    print(format_table(table, ['context', *per_value]))
    print()
    print(format_table(result['summary'], ['policy', 'split', 'mean_return', 'std_return',
                                           'switching_return', 'switches', 'judged', 'recovered',
                                           'mean_latency', 'spearman', 'probe_mse',
                                           'probe_mean_mse']))
    print()
    from zeus_ros.offline.evaluation.diagnostics import DIAGNOSTICS  # numpy only: after a run

    print(format_table(result['summary'][:1], list(DIAGNOSTICS)))
    print(f'\nwrote CSV and PNG to {result["out"]}')
    return 0


def _main_many(args: argparse.Namespace) -> int:
    """Several checkpoints (or all splits): evaluate each, then the tables over seeds."""
    from zeus_ros.learning.errors import CheckpointError
    from zeus_ros.offline.evaluation.eval_batch import evaluate_many, find_checkpoints
    from zeus_ros.offline.evaluation.evaluate import parse_values
    from zeus_ros.offline.evaluation.report import markdown_table

    if args.out is None:
        print('zeus eval: several checkpoints (or --split all) need --out', file=sys.stderr)
        return 2
    try:
        checkpoints = find_checkpoints(args.checkpoint)
        values, splits = None, None if args.split == 'all' else [args.split]
        if args.values is not None:
            from zeus_ros.learning.inference import InferenceAgent

            names = InferenceAgent.from_checkpoint(checkpoints[0],
                                                   expect_task=args.task).context_names
            values, splits = parse_values(args.values, names), ['custom']
        tables = evaluate_many(
            checkpoints, args.out, splits=splits, values=values,
            jobs=args.jobs, force=args.force, progress=not args.no_progress,
            expect_task=args.task,
            episodes=args.episodes, switch_every=args.switch_every,
            switch_episodes=args.switch_episodes, probe_steps=args.probe_steps, seed=args.seed)
    except (CheckpointError, ValueError, FileNotFoundError) as error:
        print(f'zeus eval: {error}', file=sys.stderr)
        return 2
    for task, rows in tables.items():
        print(f'\n{task}\n{markdown_table(rows)}')
    print(f'\nwrote per-run CSV/PNG, per-task tables and {args.out / "tables.md"}')
    return 0

