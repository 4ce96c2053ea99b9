"""Verified checkpoints: a file whose sha256 is recorded somewhere is refused on a mismatch.

A checkpoint decides what a robot does, and a flipped bit in a weight still loads: every
tensor is finite and the shapes fit. So a file is compared with every sha256 recorded for it:

- `--expect-sha256` (an explicit pin, from the caller);
- a sidecar `<name>.pt.sha256` (the first word: 64 hex digits, as `sha256sum` writes it);
- its card `<name>.md` (the first `| file |` or `| sha256 |` row holding 64 hex digits, as
  `zeus export` and scripts/build_zoo.py write them);
- the zoo index (the table in the `README.md` with a `<!-- zoo index` marker in the file's
  folder or the one above: checkpoints/ in the repository and in the installed share), which
  names zoo files by path relative to it with the first 12 hex digits of their sha256.

A file with none of these (what `zeus train` and the continual trainer write) loads as before,
unhashed. learning/checkpoint.py's load_checkpoint is the one loader that calls `check_file`; a
caller that already hashed the bytes (the nodes, for pairing) hands the digest over, so nothing
is hashed twice. `zeus launch` calls `verify_file` before it starts a node. No torch here: the
launcher imports this.
What this protects against, and what it does not (an attacker who can rewrite the card as
well): docs/security.md.
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
import os
from pathlib import Path
import re

__all__ = ['SIDECAR_SUFFIX', 'IntegrityError', 'Pin', 'check_file', 'parse_sha256', 'pins_for',
           'verify_file']

SIDECAR_SUFFIX = '.sha256'
"""`model.pt` is pinned by `model.pt.sha256`."""

ZOO_MARKER = '<!-- zoo index'
"""What makes a README.md the zoo index (scripts/build_zoo.py writes it)."""

_HEX64 = re.compile(r'[0-9a-f]{64}')
_CARD_ROW = re.compile(r'^\|\s*(?:file|sha256)\s*\|[^\n]*?`([0-9a-f]{64})`', re.MULTILINE)
_INDEX_ROW = re.compile(r'^\|.*?\[`([^`]+\.pt)`\]\([^)]*\).*\|\s*`([0-9a-f]{12,64})`\s*\|\s*$',
                        re.MULTILINE)


class IntegrityError(ValueError):
    """A file's bytes are not the ones recorded for it, or its record is unusable (one line).

    learning/checkpoint.py raises it as CheckpointIntegrityError (a CheckpointError).
    """


@dataclass(frozen=True, slots=True)
class Pin:
    """One recorded sha256 of a file (or, from the zoo index, its first 12 hex digits)."""

    digest: str
    """Lower-case hex: the full 64 digits or a prefix of at least 12."""
    source: str
    """Where it is recorded, for the refusal: 'its card /x/zeus.md'."""
    advice: str
    """What to do when the file does not match it."""


def parse_sha256(text: str) -> str:
    """A full sha256 as 64 hex digits (any case); ValueError (one line) for anything else."""
    digest = text.strip().lower()
    if not _HEX64.fullmatch(digest):
        raise ValueError(f'{text!r} is not a sha256 (64 hex digits, as sha256sum prints it)')
    return digest


def _read_text(path: Path) -> str | None:
    """The file's text, or None when there is no such file (a card is optional)."""
    try:
        return path.read_text(encoding='utf-8', errors='replace')
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError):
        return None


def _sidecar_pin(path: Path) -> Pin | None:
    """The sidecar's pin; an unreadable one refuses the file (a pin must not fail open)."""
    sidecar = path.with_name(path.name + SIDECAR_SUFFIX)
    try:
        text = sidecar.read_text(encoding='utf-8', errors='replace')
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError as error:
        raise IntegrityError(f'checkpoint {path}: cannot read its sidecar {sidecar} '
                              f'({error.strerror or error}); fix or remove it') from None
    words = text.split()
    try:
        digest = parse_sha256(words[0] if words else '')
    except ValueError:
        raise IntegrityError(f'checkpoint {path}: its sidecar {sidecar} holds no sha256 (64 '
                              f'hex digits); write one with: sha256sum {path.name} > '
                              f'{sidecar.name}') from None
    return Pin(digest, f'its sidecar {sidecar}',
               f'restore the file, or if you replaced it on purpose: sha256sum {path.name} > '
               f'{sidecar.name}')


def _zoo_index(path: Path) -> tuple[Path, str] | None:
    """(index README, the file's name relative to it) when a zoo index sits one or two up."""
    for root in (path.parent, path.parent.parent):
        text = _read_text(root / 'README.md')
        if text is not None and ZOO_MARKER in text:
            return root / 'README.md', path.relative_to(root).as_posix()
    return None


def _pins_at(path: Path) -> list[Pin]:
    """The sidecar, card and zoo-index pins of the file at this (absolute) location."""
    pins = []
    sidecar = _sidecar_pin(path)
    if sidecar is not None:
        pins.append(sidecar)
    zoo = _zoo_index(path)
    restore = ('restore it (git checkout -- FILE in the repository, or reinstall zeus_ros); '
               'a checkpoint of your own belongs outside the zoo folder' if zoo is not None
               else 'restore it, or export it again (zeus export writes the card anew)')
    card_text = _read_text(path.with_suffix('.md')) if path.suffix == '.pt' else None
    if card_text is not None and (match := _CARD_ROW.search(card_text)):
        pins.append(Pin(match.group(1), f'its card {path.with_suffix(".md")}', restore))
    if zoo is not None:
        index, name = zoo
        text = _read_text(index) or ''
        for listed, digest in _INDEX_ROW.findall(text):
            if listed == name:
                pins.append(Pin(digest, f'the zoo index {index}', restore))
                break
    return pins


def pins_for(path: str | Path, expect_sha256: str | None = None) -> list[Pin]:
    """Every sha256 recorded for the file at `path` (empty: nothing to verify).

    Looked up where the file is named and, for a symlink, where it really lives: a link to a
    zoo file is checked as the zoo file. ValueError for an `expect_sha256` that is no sha256.
    """
    path = Path(path)
    pins = []
    if expect_sha256:
        pins.append(Pin(parse_sha256(expect_sha256), '--expect-sha256',
                        'check that you named the right file and hash'))
    seen = set()
    for where in (Path(os.path.abspath(path)), path.resolve()):
        if where not in seen:
            seen.add(where)
            pins += [pin for pin in _pins_at(where) if pin not in pins]
    return pins


def check_file(path: str | Path, data: bytes, pins: list[Pin], sha256: str | None = None
               ) -> str:
    """The file's sha256 (hashed from `data` unless given); raises unless every pin matches.

    Raises:
        IntegrityError: one line naming the file, the expected and found sha256,
            where the expected one is recorded and what to do.
    """
    found = sha256 or hashlib.sha256(data).hexdigest()
    for pin in pins:
        if not found.startswith(pin.digest):
            raise IntegrityError(
                f'checkpoint {path}: refused: expected sha256 {pin.digest} ({pin.source}), '
                f'found {found}: the file changed since it was recorded (corrupt or '
                f'tampered); {pin.advice.replace("FILE", str(path))}')
    return found


def verify_file(path: str | Path, expect_sha256: str | None = None) -> str | None:
    """The file's sha256 when something records it (checked), else None (not even read).

    For a caller that does not load the file itself (`zeus launch`, before any node starts).
    """
    pins = pins_for(path, expect_sha256)
    if not pins:
        return None
    try:
        data = Path(path).read_bytes()
    except OSError as error:
        raise IntegrityError(f'checkpoint {path}: unreadable ({error.strerror or error})'
                             ) from None
    return check_file(path, data, pins)
