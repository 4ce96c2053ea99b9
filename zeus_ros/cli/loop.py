"""`zeus loop`: the command line of collect -> train rounds (offline/training/loop.run_loop).

The flags are parsed and checked before torch and the loop's code are imported, so --help and
a wrong path answer at once (issue 52).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import signal
import sys
from typing import Any

from zeus_ros.cli.train import own_flags
from zeus_ros.cli_args import (
    TASK_HELP,
    ZeusArgumentParser,
    at_least,
    input_path,
    seed_arg,
    task_name,
)
from zeus_ros.config_sets import SET_HELP, apply_sets, parse_sets, refuse_both, set_items
from zeus_ros.learning.method_names import METHOD_NAMES
from zeus_ros.learning.readout import READOUT_STEPS
from zeus_ros.offline.schedule_text import DEFAULT_SCHEDULE, SCHEDULE_HELP

__all__ = ['main']


LOOP_JSON = 'loop.json'
"""The loop's flags, stored in --out at the start, so `--resume` needs only --out and --rounds."""
DEFAULTS: dict[str, Any] = {'random_steps': 1500, 'steps': 1500, 'updates': None,
                            'noise': 0.2, 'schedule': DEFAULT_SCHEDULE, 'method': None,
                            'seed': None, 'device': None, 'no_eval': False, 'set': []}
STORED = ('task', 'config', *DEFAULTS)


def _build_parser() -> argparse.ArgumentParser:
    parser = ZeusArgumentParser(
        prog='zeus loop', formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Random collection -> train -> collect with the new policy -> retrain '
        '(resume), appending bags, for N rounds. The flags are stored in OUT/loop.json; '
        '--resume reads them, so `zeus loop --out OUT --rounds 6 --resume` continues a loop '
        '(a flag given again overrides the stored one).', epilog=SCHEDULE_HELP)
    parser.add_argument('--task', type=task_name, help=f'{TASK_HELP} (required unless --resume)')
    parser.add_argument('--config', type=Path,
                        help='training config YAML, e.g. params/train/state_cpu.yaml (found in '
                        'the package share too; required unless --resume)')
    parser.add_argument('--out', type=Path, required=True, help='folder for bags/ and run/')
    parser.add_argument('--rounds', type=at_least(1), default=2, help='collect+train rounds')
    parser.add_argument('--random-steps', type=at_least(0),
                        help="uniform-random steps of round 1 (default 1500, the paper's seed "
                        'steps)')
    parser.add_argument('--steps', type=at_least(0),
                        help='steps collected with the policy in each later round (default 1500)')
    parser.add_argument('--updates', type=at_least(0),
                        help='updates per round (default: the config num_updates)')
    parser.add_argument('--noise', type=at_least(0.0, float),
                        help='exploration noise, fraction of half the action range (default 0.2; '
                        "with the config's exploration: noise; exploration: stochastic samples "
                        'the SAC policy instead)')
    parser.add_argument('--schedule',
                        help='context schedule while collecting (default: '
                        f'{DEFAULTS["schedule"]}, one train value per episode in turn: the '
                        'critic can value a context that holds for the episode, and the '
                        'policy learns to adapt (docs/results.md, session 7); grammar below)')
    parser.add_argument('--set', nargs='+', action='extend', metavar='KEY=VALUE',
                        help=f'{SET_HELP}; on --resume added to the stored ones')
    parser.add_argument('--method', choices=METHOD_NAMES, help='override the config method')
    parser.add_argument('--seed', type=seed_arg, help='override the config seed')
    parser.add_argument('--device', help='override the config device: auto, cpu, cuda[:N]')
    parser.add_argument('--resume', action='store_true',
                        help='continue the loop in --out up to --rounds with its stored flags')
    parser.add_argument('--no-eval', action='store_true', default=None,
                        help='skip periodic evaluation')
    parser.add_argument('--no-progress', action='store_true', help='hide progress bars')
    parser.add_argument('--readout-steps', type=at_least(0), default=READOUT_STEPS,
                        help="after the last round, steps of the policy that fit run/final.pt's "
                        'context read-out and novelty monitor (as zeus export does); default '
                        '%(default)s, 0: none')
    parser.must_exist('--config', share=True)
    return parser


def settle_flags(args: argparse.Namespace) -> argparse.Namespace:
    """Fill the loop's flags: given > stored in OUT/loop.json (on --resume) > defaults.

    Raises ValueError for a fresh loop without --task/--config or a resume with another task.
    """
    stored: dict[str, Any] = {}
    path = args.out / LOOP_JSON
    if args.resume and path.is_file():
        try:
            stored = json.loads(path.read_text())
        except (OSError, ValueError) as error:
            raise ValueError(f'{path}: cannot read the stored flags ({error}); repeat the '
                             'flags of the first run') from None
    if args.task is not None and stored.get('task') not in (None, args.task):
        raise ValueError(f'--task {args.task}: the loop in {args.out} runs {stored["task"]}')
    if args.set is not None:  # given --set items override the stored ones field by field
        args.set = set_items({**parse_sets(stored.get('set') or [], f'{path}: set'),
                              **parse_sets(args.set)})
    for key in STORED:
        if getattr(args, key) is None:
            setattr(args, key, stored.get(key, DEFAULTS.get(key)))
    missing = [f'--{key}' for key in ('task', 'config') if getattr(args, key) is None]
    if missing:
        where = f' ({path} is missing)' if args.resume else ''
        raise ValueError(f'{" and ".join(missing)} required{where}')
    args.config = input_path(args.config, '--config').resolve()
    return args


def _store_flags(args: argparse.Namespace) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    flags = {key: str(value) if isinstance(value, Path) else value
             for key, value in vars(args).items() if key in STORED}
    (args.out / LOOP_JSON).write_text(json.dumps(flags, indent=1) + '\n')


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus loop`; returns the process exit code."""
    from zeus_ros.bags.errors import BagError, IngestError
    from zeus_ros.learning.errors import CheckpointError, ConfigError

    args = _build_parser().parse_args(argv)
    try:
        args = settle_flags(args)
    except ValueError as error:
        print(f'zeus loop: {error}', file=sys.stderr)
        return 2
    for flag in ('rounds', 'random_steps', 'steps'):
        if getattr(args, flag) < 1:
            print(f'zeus loop: --{flag.replace("_", "-")} must be >= 1', file=sys.stderr)
            return 2
    from zeus_ros.offline.rollout import parse_schedule
    from zeus_ros.offline.training.loop import run_loop
    from zeus_ros.offline.training.train import (  # torch: once the flags are good
        CHECKPOINT,
        TrainError,
        apply_overrides,
        check_device,
        read_config,
    )

    started = (args.out / 'run' / CHECKPOINT).exists() or any((args.out / 'bags').glob('bag_*'))
    if started and not args.resume:
        print(f'zeus loop: {args.out} already holds a loop run (bags or a checkpoint); pass '
              '--resume to continue it (an unfinished bag is recovered and completed) or '
              'choose another --out', file=sys.stderr)
        return 2
    try:
        sets = parse_sets(args.set)
        refuse_both(sets, own_flags(args))
        config = apply_overrides(apply_sets(read_config(args.config), sets), method=args.method,
                                 seed=args.seed, device=args.device)
        check_device(config.device, '--device' if args.device else
                     f'--config {args.config}: device')
        schedule = parse_schedule(args.schedule)
    except (ConfigError, ValueError) as error:
        print(f'zeus loop: {error}', file=sys.stderr)
        return 2
    _store_flags(args)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        run_loop(args.task, config, args.out, rounds=args.rounds,
                 random_steps=args.random_steps, steps=args.steps,
                 updates=args.updates or config.num_updates, noise=args.noise,
                 schedule=schedule, seed=config.seed, progress=not args.no_progress,
                 evaluate=not args.no_eval, resume=args.resume,
                 readout_steps=args.readout_steps)
    except (TrainError, ConfigError, CheckpointError, BagError, IngestError,
            ValueError) as error:
        print(f'zeus loop: {error}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('zeus loop: interrupted; bags and the latest checkpoint are kept in '
              f'{args.out}', file=sys.stderr)
        return 130
    except Exception as error:  # a full disk is one line (torch wraps ENOSPC); else a bug
        from zeus_ros.atomic_file import disk_full_message
        from zeus_ros.offline.rollout import CollectDiskFull

        full = str(error) if isinstance(error, CollectDiskFull) else \
            disk_full_message(error, args.out)
        if full is None:
            raise
        print(f'zeus loop: {full}; `zeus loop --resume` goes on once there is space',
              file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
