"""Where a stopped `zeus distill` run picks up: one resume point after every DAgger round.

Why: a pixel student takes 12-50 minutes per seed on a 2-core machine; a session or a Ctrl-C
that ends mid-run must lose at most the round in progress. After each round the run writes

    <out>/rounds/round_<r>.npz   the episodes collected in round r (not round 0 when it came
                                 from --data-cache: the cache itself is the record)
    <out>/resume.pt              the student's networks, Adam's state, the RNG states, the
                                 rounds' rows and what the run was asked (its fingerprint)

both atomically. `--resume` rebuilds the episode store from those files in the same order and
goes on with the next round, so a resumed run equals one that never stopped (on the same
machine and torch build). The finished run removes both; student.pt and rounds.csv stay.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from zeus_ros.atomic_file import atomic_write
from zeus_ros.learning.errors import ConfigError
from zeus_ros.offline.training.distill_data import EpisodeStore

__all__ = ['ResumePoint', 'clear_resume', 'load_resume', 'round_data_path', 'save_resume']

RESUME_FILE = 'resume.pt'
ROUNDS_FOLDER = 'rounds'
GROWABLE = ('rounds',)
"""Fingerprint fields a resume may change: more rounds continue the same run."""


@dataclass
class ResumePoint:
    """The state of a run after round `round_` (everything the next round needs)."""

    round_: int
    step: int
    rows: list[dict[str, Any]]
    modules: dict[str, dict[str, torch.Tensor]]
    optimizer: dict[str, Any]
    numpy_rng: dict[str, Any]
    torch_rng: torch.Tensor
    fingerprint: dict[str, Any]


def round_data_path(out: Path, round_: int) -> Path:
    """The episodes of round `round_` (see the module docstring)."""
    return out / ROUNDS_FOLDER / f'round_{round_}.npz'


def save_resume(out: Path, point: ResumePoint) -> Path:
    """Write `out/resume.pt` atomically (the round's episodes are already on disk)."""
    path = out / RESUME_FILE
    with atomic_write(path, 'wb') as handle:
        torch.save(point.__dict__, handle)
    return path


def load_resume(out: Path, fingerprint: dict[str, Any], store: EpisodeStore,
                data_cache: Path | None) -> ResumePoint:
    """Read `out/resume.pt`, check it was the same run, and refill `store` round by round.

    Raises:
        ConfigError: no resume point, a damaged one, another run's, or a missing round file.
    """
    path = out / RESUME_FILE
    if not path.is_file():
        raise ConfigError(f'--resume: {out} holds no stopped run ({RESUME_FILE} is missing); '
                          'start without --resume')
    try:
        saved = torch.load(path, map_location='cpu', weights_only=False)
        point = ResumePoint(**saved)
    except Exception as error:  # any decoding failure: name the file
        raise ConfigError(f'--resume: {path} cannot be read ({type(error).__name__}: '
                          f'{error}); delete {out} or give another --out') from None
    changed = sorted(key for key in fingerprint.keys() | point.fingerprint.keys()
                     if key not in GROWABLE
                     and fingerprint.get(key) != point.fingerprint.get(key))
    if changed:
        raise ConfigError(f'--resume: {path} was started with other ' + ', '.join(
            f'{key} ({point.fingerprint.get(key)!r}, now {fingerprint.get(key)!r})'
            for key in changed) + '; resume with the same arguments or give another --out')
    if fingerprint['rounds'] <= point.round_:
        raise ConfigError(f'--resume: {path} has finished round {point.round_}; '
                          f'--rounds {fingerprint["rounds"]} asks for no more')
    for round_ in range(point.round_ + 1):
        source = round_data_path(out, round_)
        if round_ == 0 and data_cache is not None:
            source = data_cache
        if not source.is_file():
            raise ConfigError(f'--resume: the episodes of round {round_} ({source}) are '
                              'missing; the run cannot continue: start it again')
        store.load(source)
    return point


def clear_resume(out: Path) -> None:
    """Remove the resume point and the round files of a finished run."""
    (out / RESUME_FILE).unlink(missing_ok=True)
    folder = out / ROUNDS_FOLDER
    if folder.is_dir():
        for path in folder.glob('round_*.npz'):
            path.unlink()
        folder.rmdir()

