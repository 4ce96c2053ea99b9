"""`zeus recover`: restore bags cut off by a crash (the library is zeus_ros/bags/recover.py).

The bag libraries (numpy, rosbags) are imported after the arguments are parsed: --help answers
at once (issue 52).
"""

from __future__ import annotations

from pathlib import Path
import sqlite3
import sys

from zeus_ros.bags.errors import BagError
from zeus_ros.cli_args import ZeusArgumentParser, flag_or_positional

__all__ = ['main']


def _bag_dirs(path: Path) -> list[Path]:
    """The bag folders at or below `path` (bags.recording.find_bags: a bag, or folders of bags)."""
    from zeus_ros.bags.recording import find_bags

    return list(dict.fromkeys(bag.parent if bag.is_file() else bag for bag in find_bags(path)))


def main(argv: list[str] | None = None) -> int:
    """`zeus recover BAG...`: restore bags cut off by a crash, say what was kept and lost."""
    parser = ZeusArgumentParser(
        prog='zeus recover', description='Restore rosbag2 bags cut off by a crash (SIGKILL, '
        'power loss of the process): rebuild the mcap summary / metadata.yaml from the data '
        'on disk. Bags closed properly are left untouched.')
    flag_or_positional(parser, '--bags', many=True, type=Path,
                       help='bag directories, or folders of bags (searched at any depth, e.g. '
                       'bags/ of `zeus launch --record`); also accepted without --bags, the old '
                       'spelling')
    parser.add_argument('--dry-run', action='store_true', help='report only, change nothing')
    parser.add_argument('--keep-original', action='store_true',
                        help='keep the damaged mcap next to the rebuilt one as *.mcap.orig')
    args = parser.parse_args(argv)
    from zeus_ros.bags.recover import recover_bag

    failed = 0
    for root in args.bags:
        try:
            if not root.exists():
                raise BagError(root, 'no such file or directory')
            for bag in _bag_dirs(root):
                report = recover_bag(bag, dry_run=args.dry_run, keep_original=args.keep_original)
                print(report.summary())
        except (BagError, OSError, sqlite3.Error) as exc:
            print(f'zeus recover: {exc}', file=sys.stderr)
            failed += 1
    return 1 if failed else 0

