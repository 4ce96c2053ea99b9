"""`zeus ingest`: the command line of reading bags as training does (offline/data/ingest.py).

The bag reader (numpy, rosbags) is imported after the arguments are parsed and the paths
found, so --help and a mistyped path answer at once (issue 52).
"""

from __future__ import annotations

from pathlib import Path
import sys
import warnings

from zeus_ros.bags.errors import BagError, IngestError
from zeus_ros.cli_args import ZeusArgumentParser, flag_or_positional

__all__ = ['main']


def main(argv: list[str] | None = None) -> int:
    """`zeus ingest --bags BAG...`: read bags as training would and say what they hold or lack."""
    parser = ZeusArgumentParser(
        prog='zeus ingest', description='Read bags exactly as `zeus train` does and report '
        'steps, episodes and every gap, duplicate or count mismatch (exit 1 if unusable).')
    flag_or_positional(parser, '--bags', many=True, type=Path,
                       help='bag directories, .mcap/.db3 files, or folders of bags, searched at '
                       'any depth (bags/ of `zeus launch --record`; as `zeus train --bags`; also '
                       'accepted without --bags)')
    parser.add_argument('--namespace', default='',
                        help='namespace of the recorded system: reads /<ns>/zeus/... topics')
    parser.add_argument('--strict', action='store_true', help='any issue is an error')
    parser.add_argument('--skip-corrupt', action='store_true',
                        help='skip (and list) bags that cannot be read')
    parser.must_exist('--bags')
    args = parser.parse_args(argv)
    from zeus_ros.offline.data.ingest import IngestWarning, ingest_bags

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always', IngestWarning)
            data = ingest_bags(args.bags, skip_corrupt=args.skip_corrupt, strict=args.strict,
                               namespace=args.namespace)
    except (BagError, IngestError) as exc:
        print(f'zeus ingest: {exc}', file=sys.stderr)
        return 1
    for warning in caught:
        print(f'warning: {warning.message}', file=sys.stderr)
    print(f'{data.task}: {len(data.episodes)} episode piece(s), {data.num_transitions} '
          f'transitions; context {", ".join(data.context_names)}')
    print(data.report.summary())
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
