"""`zeus train`: the command line of training from bags (offline/training/train.py: `train`).

The arguments are parsed and their paths checked before torch and the training code are
imported, so `--help` and a mistyped path answer at once even on a busy machine (issue 52).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
import sys
from typing import Any

from zeus_ros.bags.kinds import DEFAULT_KINDS, KINDS
from zeus_ros.cli_args import TASK_HELP, ZeusArgumentParser, at_least, seed_arg, task_name
from zeus_ros.config_sets import SET_HELP, apply_sets, parse_sets, refuse_both
from zeus_ros.learning.errors import ConfigError
from zeus_ros.learning.method_names import METHOD_NAMES
from zeus_ros.learning.readout import READOUT_STEPS

__all__ = ['main', 'own_flags']


def own_flags(args: argparse.Namespace) -> list[tuple[str, str, Any]]:
    """(config field, flag, value) of the flags that override one field, for refuse_both."""
    return [(name, flag, getattr(args, attr, None)) for name, flag, attr in (
        ('method', '--method', 'method'), ('num_updates', '--updates', 'updates'),
        ('seed', '--seed', 'seed'), ('device', '--device', 'device'))]


def _kinds(text: str) -> tuple[str, ...]:
    """The argparse type of --kinds: comma-separated kinds of bags."""
    kinds = tuple(k.strip() for k in text.split(',') if k.strip())
    wrong = [k for k in kinds if k not in KINDS]
    if wrong or not kinds:
        raise argparse.ArgumentTypeError(f'{text!r}: choose from {", ".join(KINDS)}')
    return kinds


def _build_parser() -> argparse.ArgumentParser:
    parser = ZeusArgumentParser(
        prog='zeus train', description='Train a ZeUS (or baseline) agent from bags.')
    parser.add_argument('--bags', nargs='+', required=True,
                        help='bag directories, .mcap/.db3 files, or folders of bags (searched '
                        'at any depth: bags/ of `zeus launch --record` works)')
    parser.add_argument('--kinds', type=_kinds, default=DEFAULT_KINDS, metavar='KIND[,KIND]',
                        help=f'which bags to take, by what they are ({", ".join(KINDS)}; zeus '
                        f'bags lists them); default {",".join(DEFAULT_KINDS)}: not the continual '
                        "trainer's "
                        'rehearsal. A bag that does not say counts as manual')
    parser.add_argument('--config', type=Path, required=True,
                        help='training config YAML, e.g. params/train/state_cpu.yaml')
    parser.add_argument('--out', type=Path, required=True, help='run directory, e.g. runs/x')
    parser.add_argument('--task', type=task_name,
                        help=f'expected task (error if the bags hold another); {TASK_HELP}')
    parser.add_argument('--task-file', type=Path, default=None,
                        help='YAML task file declaring the task the bags name (a robot: its '
                        'robot_bridge params; see params/robot_bridge.yaml)')
    parser.add_argument('--namespace', default='',
                        help='namespace of the recorded system: reads /<ns>/zeus/... topics '
                        '(bags of `ros2 bag record`; the recorder node needs none)')
    parser.add_argument('--strict', action='store_true',
                        help='refuse bags with any issue (gaps, NaN/Inf or wrong-length values) '
                        'instead of dropping the affected transitions and their histories')
    parser.add_argument('--set', nargs='+', action='extend', default=[], metavar='KEY=VALUE',
                        help=SET_HELP)
    parser.add_argument('--method', choices=METHOD_NAMES, help='override the config method')
    parser.add_argument('--updates', type=at_least(0),
                        help='total updates of the run (overrides num_updates; a resumed run '
                        'counts from its checkpoint step)')
    parser.add_argument('--seed', type=seed_arg, help='override the config seed')
    parser.add_argument('--device', help='override the config device: auto, cpu, cuda[:N]')
    parser.add_argument('--resume', action='store_true',
                        help='continue from OUT/checkpoint.pt (optimizers and step count)')
    parser.add_argument('--no-eval', action='store_true', help='skip periodic evaluation')
    parser.add_argument('--readout-steps', type=at_least(0), default=READOUT_STEPS,
                        help='steps of the trained policy on the train contexts that fit the '
                        "context read-out and novelty monitor stored in final.pt (as zeus "
                        "export's), so it deploys with the estimate in the context's units; "
                        'default %(default)s, 0: none')
    parser.add_argument('--threads', type=at_least(0), default=0,
                        help='torch CPU threads (0: torch default)')
    parser.add_argument('--no-progress', action='store_true', help='hide the progress bar')
    parser.must_exist('--bags')
    parser.must_exist('--config', share=True)
    parser.must_exist('--task-file')
    return parser


def _print_ingest_warnings() -> Callable[..., None]:
    """Show what ingest found (dropped values, gaps) as plain lines; returns the old hook."""
    import warnings

    from zeus_ros.offline.data.ingest import IngestWarning

    default = warnings.showwarning

    def show(message: Any, category: Any, *args: Any, **kwargs: Any) -> None:
        if issubclass(category, IngestWarning):
            print(f'zeus train: warning: {message}', file=sys.stderr)
        else:
            default(message, category, *args, **kwargs)

    warnings.showwarning = show
    return default


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus train`; returns the process exit code."""
    args = _build_parser().parse_args(argv)
    from zeus_ros.bags.errors import BagError, IngestError
    from zeus_ros.bags.kinds import choose_bags
    from zeus_ros.bags.recording import find_bags
    from zeus_ros.offline.training.train import (  # torch: only once the arguments are good
        NonFiniteError,
        TrainError,
        apply_overrides,
        check_device,
        read_config,
        train,
    )

    try:
        sets = parse_sets(args.set)
        refuse_both(sets, own_flags(args))
        config = apply_overrides(apply_sets(read_config(args.config), sets), method=args.method,
                                 updates=args.updates, seed=args.seed, device=args.device)
        check_device(config.device, '--device' if args.device else
                     f'--config {args.config}: device')
    except ConfigError as error:
        print(f'zeus train: {error}', file=sys.stderr)
        return 2
    try:  # after the config: a bad config is the first thing said, whatever the bags hold
        bags = choose_bags(find_bags(args.bags), args.kinds,
                           lambda line: print(f'zeus train: {line}', file=sys.stderr))
    except (BagError, ValueError) as error:
        print(f'zeus train: --bags: {error}', file=sys.stderr)
        return 2
    if args.threads > 0:
        import torch

        torch.set_num_threads(args.threads)
    import warnings

    if args.task_file is not None:
        from sim_bridge.registry import register_task_file

        try:
            register_task_file(args.task_file)
        except ValueError as error:
            print(f'zeus train: --task-file: {error}', file=sys.stderr)
            return 2
    default_showwarning = _print_ingest_warnings()
    try:
        train(bags, config, args.out, task=args.task, resume=args.resume,
              evaluate=not args.no_eval, progress=not args.no_progress,
              namespace=args.namespace, strict=args.strict,
              readout_steps=args.readout_steps)
    except NonFiniteError as error:
        print(f'zeus train: {error}', file=sys.stderr)
        return 1
    except (TrainError, ConfigError, BagError, IngestError) as error:
        print(f'zeus train: {error}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except Exception as error:  # torch wraps ENOSPC in a RuntimeError: look behind it
        from zeus_ros.atomic_file import disk_full_message

        full = disk_full_message(error, args.out)
        if full is None:
            raise
        from zeus_ros.offline.training.train import CHECKPOINT

        again = (f'--resume continues from {args.out / CHECKPOINT}'
                 if (args.out / CHECKPOINT).exists() else
                 'run it again (no checkpoint was written yet: nothing to resume)')
        print(f'zeus train: {full}; free some space, then {again}', file=sys.stderr)
        return 2
    finally:
        warnings.showwarning = default_showwarning
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
