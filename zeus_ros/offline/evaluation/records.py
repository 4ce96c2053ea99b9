"""What a finished `zeus eval` leaves beside its tables, and how export and report find it.

Every evaluation folder gets `eval.json` last, after its CSV and PNG files: the checkpoint it
evaluated (path and sha256), task, method, seed, split and wall seconds. So `zeus export` puts
on its card the evaluations of exactly the checkpoint it exports (wherever `zeus eval --out`
wrote them below the run folder; never those of a checkpoint retrained since), and `zeus
report` finds every finished evaluation below a folder whatever the folders are called.
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
import json
import os
from pathlib import Path
from typing import Any

from zeus_ros.atomic_file import replace_text

__all__ = ['EVAL_RECORD', 'EvalRecord', 'checkpoint_sha256', 'find_records', 'read_record',
           'write_record']

EVAL_RECORD = 'eval.json'


@dataclass(frozen=True)
class EvalRecord:
    """One finished evaluation: where its files are and what it evaluated."""

    folder: Path
    checkpoint: str
    checkpoint_sha256: str
    task: str
    method: str
    seed: int
    split: str
    seconds: float | None

    @property
    def summary(self) -> Path:
        """Its summary.csv (one row per policy)."""
        return self.folder / 'summary.csv'

    @property
    def written_ns(self) -> int:
        """When it finished (the record's modification time), to prefer the newest."""
        return (self.folder / EVAL_RECORD).stat().st_mtime_ns


def checkpoint_sha256(path: Path | str) -> str:
    """The sha256 of a checkpoint file: what identifies it across copies and renames."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_record(folder: Path, checkpoint: Path | str, *, sha256: str, task: str, method: str,
                 seed: int, split: str, seconds: float) -> Path:
    """Write `folder`/eval.json (atomically): the evaluation in it is complete."""
    data = {'checkpoint': str(Path(checkpoint).resolve()), 'checkpoint_sha256': sha256,
            'task': task, 'method': method, 'seed': int(seed), 'split': split,
            'seconds': round(float(seconds), 1)}
    path = folder / EVAL_RECORD
    replace_text(path, json.dumps(data, indent=1) + '\n')
    return path


def read_record(folder: Path) -> EvalRecord | None:
    """The record of an evaluation folder; None when it has none (unfinished, or older)."""
    try:
        data: dict[str, Any] = json.loads((folder / EVAL_RECORD).read_text())
        record = EvalRecord(folder, str(data['checkpoint']), str(data['checkpoint_sha256']),
                            str(data['task']), str(data['method']), int(data['seed']),
                            str(data['split']), data.get('seconds'))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return record if record.summary.is_file() else None


def find_records(root: Path, sha256: str | None = None) -> list[EvalRecord]:
    """Finished evaluations at or below `root` (of the checkpoint `sha256`, if given).

    One per (checkpoint, split): the newest, when the same checkpoint was evaluated into
    several folders. Hidden folders are skipped.
    """
    newest: dict[tuple[str, str], EvalRecord] = {}
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith('.'))
        if EVAL_RECORD not in files:
            continue
        record = read_record(Path(folder))
        if record is None or (sha256 is not None and record.checkpoint_sha256 != sha256):
            continue
        key = (record.checkpoint_sha256, record.split)
        if key not in newest or record.written_ns > newest[key].written_ns:
            newest[key] = record
    return sorted(newest.values(), key=lambda r: (r.task, r.method, r.seed, r.split,
                                                  str(r.folder)))
