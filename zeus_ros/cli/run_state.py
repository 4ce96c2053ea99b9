"""`python -m zeus_ros.cli.run_state`: a run folder's state for shell scripts.

    python -m zeus_ros.cli.run_state done RUN [SPLIT ...]   # exit 0: finished
    python -m zeus_ros.cli.run_state seconds RUN            # training seconds
    python -m zeus_ros.cli.run_state mark-trained RUN SECONDS
    python -m zeus_ros.cli.run_state mark-continued RUN EARLIER_SECONDS
    python -m zeus_ros.cli.run_state mark-evaluated RUN SPLIT SECONDS

The state itself is zeus_ros/offline/runs.py.
"""

from __future__ import annotations

from pathlib import Path
import sys

from zeus_ros.cli_args import ZeusArgumentParser
from zeus_ros.offline import runs

__all__ = ['main']


def main(argv: list[str] | None = None) -> int:
    """The shell scripts' access to a run's state (see zeus_ros/offline/runs.py)."""
    parser = ZeusArgumentParser(prog='python -m zeus_ros.cli.run_state',
                                description=runs.__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest='command', required=True)

    def command(name: str, summary: str, *positionals: str) -> None:
        sub = commands.add_parser(name, help=summary)
        sub.add_argument('run', type=Path, metavar='RUN', help='the run folder')
        for positional in positionals:
            if positional == 'splits':
                sub.add_argument('splits', nargs='*', metavar='SPLIT')
            else:
                sub.add_argument(positional, type=float if 'seconds' in positional else str)

    command('done', 'exit 0 when RUN is trained and every SPLIT evaluated, else 1', 'splits')
    command('seconds', "print RUN's training seconds ('' when unknown)")
    command('mark-trained', 'record that RUN is trained', 'seconds')
    command('mark-continued', 'record that RUN continues a shorter run', 'earlier_seconds')
    command('mark-evaluated', 'record that SPLIT of RUN is evaluated', 'split', 'seconds')
    args = parser.parse_args(argv)
    try:
        if args.command == 'done':
            return 0 if runs.read_state(args.run).done(args.splits) else 1
        if args.command == 'seconds':
            seconds = runs.read_state(args.run).train_seconds
            print('' if seconds is None else f'{seconds:g}')
        elif args.command == 'mark-trained':
            runs.mark_trained(args.run, args.seconds)
        elif args.command == 'mark-continued':
            runs.mark_continued(args.run, args.earlier_seconds)
        else:
            runs.mark_evaluated(args.run, args.split, args.seconds)
    except runs.RunStateError as error:
        print(f'{parser.prog}: {error}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
