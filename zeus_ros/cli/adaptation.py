"""`zeus adaptation`: the command line of the value-of-adaptation check (adaptation.py).

The library (numpy, torch, MuJoCo) is imported once the arguments are parsed and the
checkpoints found: --help and a wrong path answer at once (issue 52).
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

EVAL_SEED = 200
"""The default --seed: offline/evaluation/adaptation.EVAL_SEED (a test keeps the two equal)."""

__all__ = ['main', 'same_file']


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus adaptation`."""
    from zeus_ros.cli_args import (
        EXPECT_SHA256_HELP,
        ZeusArgumentParser,
        at_least,
        module_doc,
        seed_arg,
        sha256_arg,
    )

    parser = ZeusArgumentParser(prog='zeus adaptation',
                                description=module_doc('zeus_ros.offline.evaluation.adaptation'),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--checkpoint', type=Path, required=True, help='your checkpoint')
    parser.add_argument('--expect-sha256', type=sha256_arg, metavar='SHA256',
                        help=f'{EXPECT_SHA256_HELP} (--checkpoint; the zoo one is checked '
                        'against its card and the zoo index)')
    parser.add_argument('--against', default='zoo',
                        help="'zoo' (the family's zoo checkpoint, default), 'none', or a file")
    parser.add_argument('--episodes', type=at_least(1), default=3,
                        help='episodes per context value')
    parser.add_argument('--seed', type=seed_arg, default=EVAL_SEED, help='evaluation seed')
    parser.add_argument('--threads', type=at_least(1), default=1,
                        help='torch CPU threads (default 1: the networks act on one observation '
                        "at a time; torch's default of one per core took 33 min where one "
                        'took 36 s on a busy 2-core machine)')
    parser.add_argument('--no-progress', action='store_true')
    parser.must_exist('--checkpoint')
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f'--episodes {args.episodes}: give at least 1')
    if args.against not in ('zoo', 'none') and not Path(args.against).exists():
        parser.error(f'argument --against: {args.against}: no such file (looked in {Path.cwd()})')
    import torch

    from zeus_ros.offline.evaluation.adaptation import format_reports, measure_adaptation

    torch.set_num_threads(args.threads)
    from zeus_ros.learning.errors import CheckpointError

    try:
        mine = measure_adaptation(args.checkpoint, episodes=args.episodes, seed=args.seed,
                                  progress=not args.no_progress,
                                  expect_sha256=args.expect_sha256, label='yours')
        reports = [('yours', mine)]
        other = None
        if args.against == 'zoo':
            from zeus_ros.system.launch_defaults import zoo_checkpoint

            try:
                other = zoo_checkpoint(mine.task)
            except ValueError as error:
                print(f'zeus adaptation: no comparison: {error}', file=sys.stderr)
        elif args.against != 'none':
            other = Path(args.against)
        label = 'zoo' if args.against == 'zoo' else str(other)
        if other is not None and same_file(args.checkpoint, other):
            # Same bytes, same seed: a second measurement would print the same row again.
            print(f'zeus adaptation: your checkpoint is the {label} one (same sha256): '
                  'measured once', file=sys.stderr)
            reports = [(f'yours = {label}', mine)]
        elif other is not None:
            reports.append((label, measure_adaptation(
                other, episodes=args.episodes, seed=args.seed, progress=not args.no_progress,
                label=label)))
    except (CheckpointError, ValueError, FileNotFoundError) as error:
        print(f'zeus adaptation: {error}', file=sys.stderr)
        return 2
    print(f'{mine.task}: {args.episodes} episode(s) per value, evaluation seed {args.seed}; '
          'mean ± s.e. over the context values; adaptation = live - frozen at the training-mean '
          'context, paired')
    print(format_reports(reports))
    return 0


def same_file(one: Path, other: Path) -> bool:
    """Whether two checkpoint files hold the same bytes (sha256): one evaluation serves both."""
    from zeus_ros.offline.evaluation.records import checkpoint_sha256

    return checkpoint_sha256(one) == checkpoint_sha256(other)


if __name__ == '__main__':
    raise SystemExit(main())
