"""What every `zeus` command shares on its command line: one error style, task names, paths.

A bad value is one line on stderr naming the command, the flag, the value and the choices (or
the nearest one), then exit 2: no usage block, no traceback. A relative input path is found
where a user expects it: in the working directory, else in the installed package share (so
`--config params/train/state_cpu.yaml` works from any folder).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable, Sequence
import difflib
import os
from pathlib import Path
from typing import Any, NoReturn

__all__ = ['EXPECT_SHA256_HELP', 'SEED_MAX', 'TASK_HELP', 'ZeusArgumentParser',
           'flag_or_positional', 'input_path', 'module_doc', 'nearest', 'nearest_path',
           'seed_arg', 'sha256_arg', 'task_name']

EXPECT_SHA256_HELP = ('refuse the checkpoint unless its sha256 is this (64 hex digits, as '
                      'sha256sum prints it); a sidecar FILE.sha256, its card or the zoo index '
                      'pin it the same way, without this flag (docs/security.md)')


def _task_names() -> tuple[str, ...]:
    from sim_bridge.registry import TASK_NAMES

    return TASK_NAMES


TASK_HELP = 'task family: ' + ', '.join(_task_names()) + ', or a task file (.yaml)'


def nearest(value: str, choices: Iterable[str]) -> str:
    """'; did you mean X?' for the closest choice (case-insensitive), else ''."""
    options = list(choices)
    lowered = {c.lower(): c for c in options}
    match = difflib.get_close_matches(value.lower(), list(lowered), n=1, cutoff=0.5)
    return f"; did you mean '{lowered[match[0]]}'?" if match else ''


def task_name(value: str) -> str:
    """The argparse type of --task: a registered task name or a task file (registered here)."""
    from sim_bridge.registry import is_task_file, register_task_file

    if is_task_file(value):
        try:
            return register_task_file(input_path(value, 'task file'))
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
    names = _task_names()
    if value in names:
        return value
    raise argparse.ArgumentTypeError(
        f"unknown task '{value}' (choose from {', '.join(names)}){nearest(value, names)}")


def input_path(value: str | os.PathLike[str], flag: str) -> Path:
    """An existing input file or folder, found where a user expects it.

    As given (absolute, or relative to the working directory), else relative to the installed
    package share; a ValueError names both places.
    """
    from zeus_ros.system.launch_defaults import share_dir

    path = Path(os.path.expanduser(os.fspath(value)))
    if path.is_absolute() or path.exists():
        return path
    shared = share_dir() / path
    if shared.exists():
        return shared
    raise ValueError(f'{flag} {value}: not found in {Path.cwd()} nor in the package share '
                     f'{share_dir()}{nearest_path(path)}')


NEAREST_FOLDERS = ('params/train', 'params/tasks')
"""Share folders a bare or misplaced config / task file name is also matched against."""


def nearest_path(path: Path) -> str:
    """'; did you mean P?' for the closest existing name beside `path` (here or in the share).

    A mistyped `params/train/state_cpux.yaml` names `params/train/state_cpu.yaml`; a bare
    `state_cpux.yaml` is also matched against the share's params/train/ and params/tasks/.
    Only folder listings: no import, so the error stays at once (issue 52).
    """
    from zeus_ros.system.launch_defaults import share_dir

    shown: dict[str, str] = {}  # lower-cased name -> the path to suggest
    folders = [(path.parent, path.parent)] if path.is_absolute() else [
        (Path.cwd() / path.parent, path.parent), (share_dir() / path.parent, path.parent),
        *((share_dir() / sub, Path(sub)) for sub in NEAREST_FOLDERS)]
    for folder, prefix in folders:
        try:
            names = sorted(entry.name for entry in folder.iterdir())[:_MAX_NAMES]
        except OSError:
            continue
        for name in names:
            shown.setdefault(name.lower(), os.fspath(prefix / name))
    match = difflib.get_close_matches(path.name.lower(), list(shown), n=1, cutoff=0.75)
    return f"; did you mean '{shown[match[0]]}'?" if match else ''


_MAX_NAMES = 2000
"""Names read per folder at most: a huge working directory must not slow the error."""


def module_doc(name: str) -> str:
    """The docstring of module `name`, read from its source without importing it.

    A command's --help shows its library's docstring; importing the library would import torch.
    """
    import ast
    import importlib.util

    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        return ''
    return ast.get_docstring(ast.parse(Path(spec.origin).read_text(encoding='utf-8'))) or ''


def at_least(minimum: float, kind: type = int, maximum: float | None = None
             ) -> Callable[[str], Any]:
    """An argparse `type`: a number of `kind` within [minimum, maximum], else a one-line error.

    `--threads -2` or `--rounds 0` would otherwise start and fail later, or run silently wrong.
    """
    what = 'an integer' if kind is int else 'a number'

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not {what}') from None
        if not value >= minimum or (maximum is not None and not value <= maximum):
            bound = f'>= {minimum:g}' if maximum is None else f'in [{minimum:g}, {maximum:g}]'
            raise argparse.ArgumentTypeError(f'{text} must be {what} {bound}')
        return value

    parse.__name__ = f'{kind.__name__} >= {minimum:g}'
    return parse


SEED_MAX = 2**32 - 1
"""The largest seed numpy takes (np.random.seed, RandomState): seeds are 0 .. 2**32 - 1."""


def seed_arg(text: str) -> int:
    """The argparse `type` of --seed: an integer in numpy's range 0 .. 2**32 - 1, else one line.

    A larger seed would start the run and fail in numpy with a traceback (issue 49).
    """
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not an integer') from None
    if not 0 <= value <= SEED_MAX:
        raise argparse.ArgumentTypeError(f'{text} must be an integer in [0, {SEED_MAX}] '
                                         "(numpy's seed range)")
    return value


def sha256_arg(text: str) -> str:
    """The argparse `type` of --expect-sha256: 64 hex digits (lower-cased), else one line."""
    from zeus_ros.integrity import parse_sha256

    try:
        return parse_sha256(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


class ZeusArgumentParser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line `zeus X: argument --f: ... (choose from ...)`."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._zeus_aliases: list[tuple[str, str, bool]] = []
        self._zeus_paths: list[tuple[str, str, bool]] = []

    def must_exist(self, flag: str, *, share: bool = False) -> None:
        """Refuse `flag`'s file(s) or folder(s) in parse_args when they do not exist.

        Checked once every value has parsed (a bad value is still the first thing said) and
        before a command imports torch or MuJoCo, so a mistyped path is reported at once, not
        after a minute of imports on a busy machine (issue 52). With `share`, a path missing
        here may be in the package share (input_path); the value stays as given.
        """
        self._zeus_paths.append((flag, flag.lstrip('-').replace('-', '_'), share))

    def parse_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                   namespace: argparse.Namespace | None = None) -> argparse.Namespace:
        """Parse, then fold the deprecated positional spellings into their flags."""
        parsed = super().parse_args(args, namespace)
        for flag, dest, many in self._zeus_aliases:
            given, old = getattr(parsed, dest), getattr(parsed, f'_{dest}')
            delattr(parsed, f'_{dest}')
            values = [*(given if many and given else [] if given is None else [given]), *old]
            if not values:
                self.error(f'the following arguments are required: {flag}')
            if not many and len(values) > 1:
                self.error(f'argument {flag}: expected one value, got {len(values)}')
            setattr(parsed, dest, values if many else values[0])
        for flag, dest, share in self._zeus_paths:
            given = getattr(parsed, dest, None)
            for value in given if isinstance(given, list) else [given]:
                if value is not None:
                    problem = _missing_path(value, flag, share)
                    if problem:
                        self.error(f'argument {flag}: {problem}')
        return parsed

    def error(self, message: str) -> NoReturn:
        """Print one line (with the nearest choice for an invalid one) and exit 2."""
        if 'invalid choice:' in message and '(choose from' in message:
            value = message.split('invalid choice:', 1)[1].split('(choose from', 1)[0]
            value = value.strip().strip("'\"")
            choices = [c.strip().strip("'\"") for c in
                       message.rsplit('(choose from', 1)[1].rstrip(')').split(',')]
            message += nearest(value, choices)
        self.exit(2, f'{self.prog}: {message} (see {self.prog} --help)\n')


def _missing_path(value: str | os.PathLike[str], flag: str, share: bool) -> str:
    """Why `value` is not an existing input path ('' when it is one)."""
    if share:
        try:
            input_path(value, flag)
        except ValueError as error:
            return str(error).removeprefix(f'{flag} ')
        return ''
    path = Path(os.path.expanduser(os.fspath(value)))
    if path.exists():
        return ''
    return (f'{os.fspath(value)}: no such file or folder (looked in {Path.cwd()})'
            f'{nearest_path(path)}')


def flag_or_positional(parser: ZeusArgumentParser, flag: str, *, many: bool,
                       **kwargs: Any) -> None:
    """Add `--flag VALUE` plus the old positional spelling, kept as a silent alias.

    Call `parser.parse_args` through ZeusArgumentParser.parse_args, which merges the two.
    """
    dest = flag.lstrip('-').replace('-', '_')
    parser.add_argument(flag, nargs='+' if many else None, dest=dest, **kwargs)
    typed = {'type': kwargs['type']} if 'type' in kwargs else {}
    parser.add_argument(f'_{dest}', nargs='*', help=argparse.SUPPRESS, **typed)
    parser._zeus_aliases.append((flag, dest, many))
