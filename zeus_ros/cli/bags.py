"""`zeus bags`: one line per bag of a folder: kind, task, steps, duration, when, checkpoint.

What `zeus train --bags` would take (by kind, bags/kinds.py) is then visible before training;
it reads each bag's label and metadata.yaml, never a message, so it answers at once.
"""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
import sys
from typing import Any

from zeus_ros.bags.kinds import bag_kind, read_label
from zeus_ros.bags.recording import bag_metadata, split_steps
from zeus_ros.cli_args import ZeusArgumentParser

__all__ = ['main']


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus bags`; returns the process exit code."""
    from zeus_ros.bags.errors import BagError
    from zeus_ros.bags.kinds import DEFAULT_KINDS
    from zeus_ros.bags.recording import find_bags

    parser = ZeusArgumentParser(prog='zeus bags', description=__doc__.splitlines()[0])
    parser.add_argument('folder', nargs='*', type=Path, default=[Path('bags')],
                        help='bag folders, .mcap/.db3 files or folders of bags, searched at any '
                        'depth (default: bags)')
    args = parser.parse_args(argv)
    try:
        bags = find_bags(args.folder)
    except BagError as error:
        print(f'zeus bags: {error}', file=sys.stderr)
        return 2
    rows = [_row(bag) for bag in bags]
    print(f'{"kind":<10} {"task":<18} {"steps":>7} {"duration":>9}  {"when":<19}  checkpoint  '
          '(bag)')
    for row in rows:
        steps = '?' if row['steps'] is None else str(row['steps'])
        duration = '?' if row['duration_s'] is None else f'{row["duration_s"]:.1f} s'
        print(f'{row["kind"]:<10} {row["task"]:<18} {steps:>7} {duration:>9}  '
              f'{row["when"]:<19}  {row["checkpoint"]}  ({row["path"]})')
    print(f'{len(rows)} bag(s); zeus train --bags takes {", ".join(DEFAULT_KINDS)} unless '
          '--kinds says otherwise (KIND?: a bag that does not say, judged by its folder)')
    return 0


def _row(bag: Path) -> dict[str, Any]:
    """One bag for `zeus bags`: kind, task, steps, duration [s], when, checkpoint, path."""
    label = read_label(bag) if bag.is_dir() else None
    info = bag_metadata(bag) if bag.is_dir() else {}
    start = (info.get('starting_time') or {}).get('nanoseconds_since_epoch')
    duration = (info.get('duration') or {}).get('nanoseconds')
    when = label.when if label is not None and label.when else (
        datetime.fromtimestamp(int(start) / 1e9).strftime('%Y-%m-%dT%H:%M:%S') if start else '')
    kind, said = bag_kind(bag)
    return {'kind': kind if said else f'{kind}?',
            'task': (label.task if label is not None else '') or '?',
            'steps': split_steps(bag) if bag.is_dir() else None,
            'duration_s': None if duration is None else int(duration) / 1e9,
            'when': when or '?',
            'checkpoint': (label.checkpoint if label is not None else '') or '-',
            'path': bag}


if __name__ == '__main__':
    raise SystemExit(main())
