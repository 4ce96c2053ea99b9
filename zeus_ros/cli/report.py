"""`zeus report`: the tables over seeds (offline/evaluation/report.py), or a continual run.

A folder that is a `zeus launch --continual` recording or its `_continual` folder is reported
by offline/evaluation/continual_report.py: returns per segment over time, every decision.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

from zeus_ros.cli_args import ZeusArgumentParser, flag_or_positional

__all__ = ['main']


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus report`; returns the process exit code."""
    parser = ZeusArgumentParser(prog='zeus report', description=(
        '`zeus report`: mean and standard error over seeds of `zeus eval` summaries per method, '
        "split; of a continual run's recording (bags/continual_<date>) or its _continual "
        'folder: return per context segment over time with every round, gate, swap and '
        'rollback.'))
    flag_or_positional(parser, '--folder', many=False, type=Path,
                       help='folder of one task whose evaluations to report, searched at any '
                       'depth: a run folder (runs/x, where `zeus eval --checkpoint '
                       'runs/x/final.pt` writes eval_<split>/ by default), a folder of runs, or '
                       'a sweep / `zeus eval --out` folder (also accepted without --folder, the '
                       'old spelling); or a `zeus launch --continual` recording or its '
                       '_continual folder')
    parser.add_argument('--out', type=Path,
                        help='folder for CSV, MD and PNG (default: FOLDER/report; a continual '
                        'run: its _continual folder)')
    parser.add_argument('--title', help="plot title (default: the folder's task name)")
    parser.must_exist('--folder')
    args = parser.parse_args(argv)
    from zeus_ros.offline.evaluation.continual_report import continual_folders

    if continual_folders(args.folder) is not None:
        return _continual(args.folder, args.out, args.title)
    return _training(args)


def _training(args: argparse.Namespace) -> int:
    """The tables over seeds of the evaluations below --folder (torch: imported here)."""
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


def _continual(folder: Path, out: Path | None, title: str | None) -> int:
    """The report of a continual run: CSVs and picture, then a short summary."""
    from zeus_ros.offline.evaluation.continual_report import (
        FILES,
        ContinualReportError,
        write_continual_report,
    )

    try:
        result = write_continual_report(folder, out, title)
    except ContinualReportError as error:
        print(f'zeus report: {error}', file=sys.stderr)
        return 2
    print(result.summary())
    print(f'\nwrote {", ".join(FILES)} to {out if out is not None else result.folders.trainer}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
