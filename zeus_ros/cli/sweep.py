"""`zeus sweep`: the command line of a sweep (offline/training/sweep.py: plan, run_sweep).

The library (torch, Ray) is imported once the flags are parsed and checked: --help and a wrong
path answer at once (issue 52).
"""

from __future__ import annotations

import argparse
from pathlib import Path
import signal
import sys

__all__ = ['main']


def _build_parser() -> argparse.ArgumentParser:
    from zeus_ros.cli_args import (
        TASK_HELP,
        ZeusArgumentParser,
        at_least,
        module_doc,
        task_name,
    )
    from zeus_ros.learning.method_names import METHOD_NAMES

    doc = module_doc('zeus_ros.offline.training.sweep')
    parser = ZeusArgumentParser(
        prog='zeus sweep', formatter_class=argparse.RawDescriptionHelpFormatter,
        description=doc.split('\n\n')[0].split(': ', 1)[1],
        epilog=doc.split('\n\n', 2)[2])
    parser.add_argument('--tasks', nargs='+', required=True, type=task_name,
                        help=f'{TASK_HELP}; several')
    parser.add_argument('--methods', nargs='+', required=True, choices=METHOD_NAMES,
                        help='%(choices)s; several')
    parser.add_argument('--seeds', default='0', help='e.g. 0-4 or 0,2,5 (default: 0)')
    parser.add_argument('--set', action='append', default=[], metavar='KEY=V1[,V2...]',
                        help='training config override; several values make a grid axis')
    parser.add_argument('--config', type=Path,
                        help='base training config (default: params/train/state_cpu.yaml)')
    parser.add_argument('--out', type=Path, required=True, help='sweep folder (shared)')
    parser.add_argument('--rounds', type=at_least(1), default=5, help='loop rounds (default: 5)')
    parser.add_argument('--random-steps', type=at_least(0), default=1500)
    parser.add_argument('--steps', type=at_least(0), default=2000,
                        help='policy steps per later round')
    parser.add_argument('--updates', type=at_least(0), default=2000, help='updates per round')
    parser.add_argument('--noise', type=at_least(0.0, float), default=0.2)
    parser.add_argument('--schedule', help='collection schedule (default: switch:train, '
                        'every min(100, episode/2) steps)')
    parser.add_argument('--eval-splits', help='comma-separated (default: every split the '
                        'task defines)')
    parser.add_argument('--eval-episodes', type=at_least(1), help="episodes per context value "
                        "(default: zeus eval's)")
    parser.add_argument('--no-eval', action='store_true', help='train only')
    parser.add_argument('--cpus-per-trial', type=at_least(1), default=1,
                        help='CPUs (= torch threads) per trial (default: 1)')
    parser.add_argument('--gpus-per-trial', type=at_least(0.0, float),
                        help='GPUs per trial (default: 1 for pixel configs when the cluster '
                        'has GPUs, else 0)')
    parser.add_argument('--num-cpus', type=at_least(1),
                        help='CPUs of a local Ray instance (default: all cores)')
    parser.add_argument('--address', help='Ray cluster to join (default: RAY_ADDRESS; '
                        'none: a local loopback-only instance)')
    parser.add_argument('--retries', type=at_least(0), default=1, help='retries of a failed trial')
    parser.add_argument('--dry-run', action='store_true', help='list the trials and stop')
    parser.must_exist('--config', share=True)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus sweep`; returns 0, 1 (a trial failed) or 2 (bad input)."""
    args = _build_parser().parse_args(argv)
    from zeus_ros.learning.errors import ConfigError
    from zeus_ros.offline.runs import RunStateError
    from zeus_ros.offline.training.sweep import (  # torch and Ray: once the flags are good
        SweepError,
        default_config,
        parse_seeds,
        parse_sets,
        plan,
        run_sweep,
        write_status,
        write_tables,
    )
    from zeus_ros.offline.training.train import read_config
    from zeus_ros.offline.training.trial import LoopProtocol, trial_done

    try:
        for flag in ('rounds', 'random_steps', 'steps', 'updates', 'cpus_per_trial'):
            if getattr(args, flag) < 1:
                raise SweepError(f'--{flag.replace("_", "-")} must be >= 1')
        protocol = LoopProtocol(rounds=args.rounds, random_steps=args.random_steps,
                                steps=args.steps, updates=args.updates, noise=args.noise,
                                schedule=args.schedule, eval_episodes=args.eval_episodes)
        splits = [s.strip() for s in args.eval_splits.split(',')] if args.eval_splits else None
        trials = plan(args.tasks, args.methods, parse_seeds(args.seeds), parse_sets(args.set),
                      read_config(args.config or default_config()), args.out.resolve(),
                      protocol, splits,
                      evaluate=not args.no_eval)
    except (SweepError, ConfigError) as error:
        print(f'zeus sweep: {error}', file=sys.stderr)
        return 2
    if args.dry_run:
        for trial in trials:
            print(f'{trial.name}{"  (finished)" if trial_done(trial) else ""}')
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    try:
        result = run_sweep(trials, address=args.address, num_cpus=args.num_cpus,
                           cpus_per_trial=args.cpus_per_trial,
                           gpus_per_trial=args.gpus_per_trial, retries=args.retries,
                           # after ray.init, which installs its own: SIGTERM stops like Ctrl-C
                           on_start=lambda: signal.signal(signal.SIGTERM,
                                                          signal.default_int_handler))
    except (SweepError, RunStateError) as error:
        print(f'zeus sweep: {error}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'zeus sweep: interrupted; finished trials are kept in {args.out}, a rerun '
              'resumes the others', file=sys.stderr)
        return 130
    status = write_status(trials, result, args.out.resolve())
    tables = write_tables(trials, args.out.resolve())
    if tables:
        print(f'\n{tables}')
    print(f'sweep: {len(result.done)} ran, {len(result.skipped)} skipped, '
          f'{len(result.failed)} failed; trials in {status}, tables in {args.out / "tables.md"}')
    for why in result.failed.values():
        print(f'sweep: failed: {why}', file=sys.stderr)
    return 1 if result.failed else 0


if __name__ == '__main__':
    raise SystemExit(main())
