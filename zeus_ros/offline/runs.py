"""Experiment state of one run folder in one JSON file, `<run>/state.json`.

A run (`<group>/<method>_s<seed>/`, written by `zeus sweep` trials, experiments/run_one.sh and
`zeus eval` on many checkpoints) is trained, then evaluated per split. What is finished, and
how long it took, is recorded here:

    {"train": {"seconds": 812.0, "earlier_seconds": 300.0},
     "eval": {"interpolation": {"seconds": 41.5}, "extrapolation": {"seconds": 40.2}}}

`earlier_seconds`: a longer run resumed from a shorter one, that one's training time (recorded
when the copy starts; the run counts as trained once `seconds` is there). Folders from before
this file hold marker files instead: `.done_train`, `.done_train_first`, `eval_<split>/.done`,
each holding wall seconds; they are read as the same state, state.json winning where both say
something. Writers lock the folder (several evaluations of one run finish in parallel) and
replace the file atomically. It sits beside rollout.py, below training/ (which marks runs
trained) and evaluation/ (which marks splits evaluated and reports finished runs). Shell
scripts (experiments/run_one.sh, run_queue.sh) use the command line, zeus_ros/cli/run_state.py:

    python -m zeus_ros.cli.run_state done RUN [SPLIT ...]   # exit 0: finished
    python -m zeus_ros.cli.run_state seconds RUN            # training seconds
    python -m zeus_ros.cli.run_state mark-trained RUN SECONDS
    python -m zeus_ros.cli.run_state mark-continued RUN EARLIER_SECONDS
    python -m zeus_ros.cli.run_state mark-evaluated RUN SPLIT SECONDS
"""

from __future__ import annotations

from collections.abc import Iterator
import contextlib
from dataclasses import dataclass, field
import fcntl
import json
import os
from pathlib import Path
from typing import Any

from zeus_ros.atomic_file import replace_text

__all__ = ['STATE_FILE', 'RunState', 'RunStateError', 'mark_continued',
           'mark_evaluated', 'mark_trained', 'read_state']

STATE_FILE = 'state.json'


class RunStateError(ValueError):
    """A run's state.json cannot be read: the message names it and what to do."""


@dataclass
class RunState:
    """What is finished in one run folder; seconds are None when a marker held no number."""

    trained: bool = False
    train_seconds: float | None = None
    earlier_train_seconds: float | None = None
    evaluated: dict[str, float | None] = field(default_factory=dict)
    """Split -> wall seconds of its evaluation, for every split evaluated."""

    def done(self, splits: list[str] | tuple[str, ...]) -> bool:
        """Trained and every split in `splits` evaluated."""
        return self.trained and all(split in self.evaluated for split in splits)


def _marker_seconds(path: Path) -> tuple[bool, float | None]:
    """(exists, seconds) of an old marker file."""
    try:
        text = path.read_text().strip()
    except OSError:
        return False, None
    try:
        return True, float(text)
    except ValueError:
        return True, None


def _read_json(folder: Path) -> dict[str, Any]:
    path = folder / STATE_FILE
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as error:
        raise RunStateError(f'{path}: unreadable run state ({error}); delete it to re-run the '
                         "run's steps, or restore it") from None
    if not isinstance(data, dict):
        raise RunStateError(f'{path}: expected a JSON object, got {type(data).__name__}')
    return data


def read_state(folder: Path) -> RunState:
    """The state of a run folder: state.json, completed by the old marker files."""
    state = RunState()
    trained, state.train_seconds = _marker_seconds(folder / '.done_train')
    state.trained = trained
    _, state.earlier_train_seconds = _marker_seconds(folder / '.done_train_first')
    for marker in sorted(folder.glob('eval_*/.done')):
        state.evaluated[marker.parent.name.removeprefix('eval_')] = _marker_seconds(marker)[1]
    data = _read_json(folder)
    train = data.get('train')
    if isinstance(train, dict):
        if 'seconds' in train:  # only earlier_seconds: a continued run not trained yet
            state.trained = True
            state.train_seconds = train['seconds']
        state.earlier_train_seconds = train.get('earlier_seconds', state.earlier_train_seconds)
    for split, entry in (data.get('eval') or {}).items():
        state.evaluated[split] = entry.get('seconds') if isinstance(entry, dict) else None
    return state


@contextlib.contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """An exclusive lock on the run folder itself (no lock file left behind)."""
    folder.mkdir(parents=True, exist_ok=True)
    descriptor = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)
        yield
    finally:
        os.close(descriptor)  # releases the lock


def _update(folder: Path, change: Any) -> None:

    with _locked(folder):
        data = _read_json(folder)
        change(data)
        replace_text(folder / STATE_FILE, json.dumps(data, indent=1, sort_keys=True) + '\n')


def mark_trained(folder: Path, seconds: float) -> None:
    """Record that the run is trained, with its training wall seconds."""
    _update(folder, lambda data: data.setdefault('train', {}).update(seconds=round(seconds, 1)))


def mark_continued(folder: Path, earlier_seconds: float) -> None:
    """Record that the run continues a finished shorter one that trained `earlier_seconds`."""
    _update(folder, lambda data: data.setdefault('train', {}).update(
        earlier_seconds=round(earlier_seconds, 1)))


def mark_evaluated(folder: Path, split: str, seconds: float) -> None:
    """Record that `split` is evaluated (its results in eval_<split>/), with its wall seconds."""
    _update(folder, lambda data: data.setdefault('eval', {}).update(
        {split: {'seconds': round(seconds, 1)}}))
