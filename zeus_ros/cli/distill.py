"""`zeus distill`: the command line of a pixel student from a state teacher.

The distillation itself (DAgger rounds, the regression, the student) is
zeus_ros/offline/training/distill.py; this module reads the command line, checks its paths,
and only then imports torch and the library (issue 52: --help and a wrong path answer at once).
"""

from __future__ import annotations

import argparse
from dataclasses import asdict
from pathlib import Path
import sys

from zeus_ros.learning.errors import CheckpointError, ConfigError
from zeus_ros.offline.training.distill_settings import DEFAULT_CONFIG, DistillSettings

__all__ = ['main']


def _build_parser() -> argparse.ArgumentParser:
    from zeus_ros.cli_args import (
        TASK_HELP,
        ZeusArgumentParser,
        module_doc,
        seed_arg,
        task_name,
    )

    parser = ZeusArgumentParser(prog='zeus distill',
                                description=module_doc('zeus_ros.offline.training.distill'),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--task', required=True, type=task_name, help=TASK_HELP)
    parser.add_argument('--teacher', type=Path, required=True,
                        help="a state checkpoint of the task (the zoo's zeus.pt)")
    parser.add_argument('--out', type=Path, required=True, help='folder for student.pt')
    parser.add_argument('--config', type=Path, default=DEFAULT_CONFIG,
                        help='pixel network config (default: params/train/pixels_student.yaml)')
    parser.add_argument('--seed', type=seed_arg, help='override the config seed')
    parser.add_argument('--data-cache', type=Path,
                        help="round 0's teacher data: read when the file exists, else "
                        'written (the seeds of a comparison share it)')
    defaults = DistillSettings()
    for name, value in asdict(defaults).items():
        flag = '--' + name.replace('_', '-')
        if isinstance(value, bool):
            parser.add_argument(flag, action='store_true', help='student without psi')
        else:
            parser.add_argument(flag, type=type(value), default=value,
                                help=f'(default: {value})')
    parser.add_argument('--resume', action='store_true',
                        help='continue the stopped run in --out after its last finished round '
                        '(same arguments; --rounds may grow)')
    parser.add_argument('--refresh', type=Path, metavar='STUDENT',
                        help='no distillation: write --out/student.pt, the `--head teacher` '
                        "STUDENT acting with --teacher's actor (a continual round's candidate "
                        "of STUDENT's teacher: the same psi), in a second")
    parser.add_argument('--threads', type=int, default=1, help='torch threads (default: 1)')
    parser.add_argument('--no-progress', action='store_true')
    parser.must_exist('--teacher')
    parser.must_exist('--refresh')
    parser.must_exist('--config', share=True)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus distill`; one line on stderr for bad input."""
    args = _build_parser().parse_args(argv)
    import torch

    from zeus_ros.cli_args import input_path
    from zeus_ros.learning.config import load_config
    from zeus_ros.offline.training.distill import distill

    torch.set_num_threads(args.threads)
    if args.refresh is not None:
        return _refresh(args.refresh, args.teacher, args.out, args.task)
    try:
        settings = DistillSettings(**{name: getattr(args, name)
                                      for name in DistillSettings.__dataclass_fields__})
    except ConfigError as error:
        print(f'zeus distill: {error}', file=sys.stderr)
        return 2
    if settings.rounds < 1 or settings.first_steps < 1 or settings.window < 1:
        print('zeus distill: --rounds, --first-steps and --window must be >= 1', file=sys.stderr)
        return 2
    try:
        config = load_config(input_path(args.config, '--config'))
        if args.seed is not None:
            config = config.replace(seed=args.seed)
        path = distill(args.task, args.teacher, config, settings, args.out,
                       data_cache=args.data_cache, progress=not args.no_progress,
                       resume=args.resume)
    except (CheckpointError, ConfigError, ValueError) as error:
        print(f'zeus distill: {error}', file=sys.stderr)
        return 2
    except Exception as error:  # torch wraps ENOSPC in a RuntimeError: look behind it
        from zeus_ros.atomic_file import disk_full_message

        full = disk_full_message(error, args.out)
        if full is None:
            raise
        from zeus_ros.offline.training.distill_resume import RESUME_FILE

        again = ('run it again with --resume (it continues after the last finished round)'
                 if (args.out / RESUME_FILE).exists()
                 else 'run it again (no round finished: nothing to resume)')
        print(f'zeus distill: {full}; free some space and {again}', file=sys.stderr)
        return 2
    print(f'wrote {path}')
    return 0


def _refresh(student: Path, teacher: Path, out: Path, task: str) -> int:
    """`--refresh`: the student takes the retrained teacher's actor (student_refresh.py)."""
    from zeus_ros.offline.training.student_refresh import refresh_student

    try:
        path = refresh_student(student, teacher, out / 'student.pt', task=task)
    except (CheckpointError, ValueError) as error:
        print(f'zeus distill: {error}', file=sys.stderr)
        return 2
    print(f'wrote {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
