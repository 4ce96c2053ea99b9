"""`zeus report`: the command line of the tables over seeds (offline/evaluation/report.py)."""

from __future__ import annotations

from pathlib import Path
import sys

from zeus_ros.cli_args import ZeusArgumentParser, flag_or_positional
from zeus_ros.offline.evaluation import report
from zeus_ros.offline.evaluation.report import (
    ReportError,
    diagnostics_table,
    headroom_rows,
    headroom_table,
    markdown_table,
    per_run,
    write_report,
)
from zeus_ros.offline.runs import RunStateError

__all__ = ['main']


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus report`; returns the process exit code."""
    parser = ZeusArgumentParser(prog='zeus report', description=report.__doc__.splitlines()[0])
    flag_or_positional(parser, '--folder', many=False, type=Path,
                       help='folder of one task whose evaluations to report, searched at any '
                       'depth: a run folder (runs/x, where `zeus eval --checkpoint '
                       'runs/x/final.pt` writes eval_<split>/ by default), a folder of runs, or '
                       'a sweep / `zeus eval --out` folder (also accepted without --folder, the '
                       'old spelling)')
    parser.add_argument('--out', type=Path,
                        help='folder for CSV, MD and PNG (default: FOLDER/report)')
    parser.add_argument('--title', help="plot title (default: the folder's task name)")
    args = parser.parse_args(argv)
    out = args.out if args.out is not None else args.folder / 'report'
    try:
        if not args.folder.is_dir():
            raise ReportError(f'--folder {args.folder}: no such folder')
        rows = write_report(args.folder, out, args.title)
    except (ReportError, RunStateError) as error:
        print(f'zeus report: {error}', file=sys.stderr)
        return 2
    print(markdown_table(rows))
    print(f'\n{diagnostics_table(rows)}')
    headroom = headroom_rows(per_run(args.folder))
    if headroom:
        print(f'\n{headroom_table(headroom)}')
    print(f'\nwrote summary.csv, runs.csv, table.md, diagnostics.md, headroom.md, '
          f'wall_times.md and returns.png to {out}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
