"""`zeus export`: the command line of the deployment export and its card (evaluation/export.py)."""

from __future__ import annotations

from pathlib import Path
import sys

from zeus_ros.cli_args import ZeusArgumentParser, at_least
from zeus_ros.learning.readout import READOUT_STEPS
from zeus_ros.offline.evaluation import export as library
from zeus_ros.offline.evaluation.export import export, find_evaluations

__all__ = ['main']


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus export`; returns the process exit code."""
    from zeus_ros.learning.errors import CheckpointError

    parser = ZeusArgumentParser(prog='zeus export', description=library.__doc__.splitlines()[0])
    parser.add_argument('--checkpoint', type=Path, required=True, help='training checkpoint')
    parser.add_argument('--out', type=Path, required=True, help='deployment checkpoint (.pt)')
    parser.add_argument('--evals', type=Path,
                        help="where the card's returns come from (default: the evaluations of "
                        "this checkpoint that `zeus eval` wrote below the checkpoint's folder, "
                        'eval_<split>/ by default, or in the sweep trial folder above it); a '
                        'folder with eval_<split>/ folders or one evaluation folder')
    parser.add_argument('--command',
                        help='command that trained it, for checkpoints that did not record one')
    parser.add_argument('--commit',
                        help='source commit it was trained on, for checkpoints without one')
    parser.add_argument('--readout-steps', type=at_least(0), default=READOUT_STEPS,
                        help='steps of the policy on the train contexts that calibrate the '
                        'context read-out (psi -> context units, on zeus/context_readout) and '
                        'the novelty monitor (distance from the training contexts, on '
                        'zeus/context_novelty and /diagnostics) stored in the export; default '
                        '%(default)s, 0: none')
    args = parser.parse_args(argv)
    if args.out.suffix != '.pt':
        print(f'zeus export: --out {args.out} must end in .pt', file=sys.stderr)
        return 2
    if args.out.resolve() == args.checkpoint.resolve():
        print('zeus export: --out must differ from --checkpoint', file=sys.stderr)
        return 2
    for flag, path in (('--checkpoint', args.checkpoint), ('--evals', args.evals)):
        if path is not None and not path.exists():
            print(f'zeus export: {flag} {path}: no such file or folder', file=sys.stderr)
            return 2
    try:
        summaries = find_evaluations(args.checkpoint, args.evals)
        pt, card = export(args.checkpoint, args.out, command=args.command, commit=args.commit,
                          readout_steps=max(args.readout_steps, 0), summaries=summaries)
    except (CheckpointError, ValueError) as error:
        print(f'zeus export: {error}', file=sys.stderr)
        return 2
    except Exception as error:  # torch wraps ENOSPC in a RuntimeError: look behind it
        from zeus_ros.atomic_file import disk_full_message

        full = disk_full_message(error, args.out)
        if full is None:
            raise
        print(f'zeus export: {full}; free some space and run it again', file=sys.stderr)
        return 2
    before, after = args.checkpoint.stat().st_size, pt.stat().st_size
    print(f'zeus export: {pt} ({after / 1e6:.2f} MB, {before / after:.1f}x smaller) and {card}')
    scored = ', '.join(f'{split} ({path.parent})' for split, path in summaries.items())
    print(f'zeus export: the card shows the evaluations of {scored}' if scored else
          f'zeus export: no evaluation of {args.checkpoint} found below '
          f'{args.checkpoint.parent} (run `zeus eval --checkpoint {args.checkpoint}` first, '
          'or give --evals): the card says "Not evaluated yet"')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
