"""Atomic file writes: a temp file beside the target, then one rename.

Readers never see half a file and a kill never leaves one (metadata.yaml, run state, CSV
tables, checkpoints). The temp name holds the process and thread, so two jobs writing the same
file at once (parallel evaluation splits) each rename a whole file of their own. The data are
fsynced before the rename and the folder after it, so a power cut leaves the old file or the
new one, never an empty name (a rename alone survives kill -9, not a lost page cache). Temp files
that a killed writer left beside the target are removed by the next write of that target.
"""

from __future__ import annotations

from contextlib import contextmanager
import os
from pathlib import Path
import threading
from typing import IO, TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Iterator

__all__ = ['atomic_write', 'fsync_folder', 'remove_stale_temps', 'replace_text']


@contextmanager
def atomic_write(path: str | Path, mode: str = 'w', **open_args: Any) -> Iterator[IO[Any]]:
    """Open a temp file for writing; on a clean exit it replaces `path`, else it is removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(path)
    tmp = path.with_name(f'{_temp_prefix(path)}{os.getpid()}-{threading.get_ident()}')
    try:
        with tmp.open(mode, **open_args) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        tmp.replace(path)
        fsync_folder(path.parent)
    finally:
        tmp.unlink(missing_ok=True)


def _temp_prefix(path: Path) -> str:
    return f'.{path.name}.tmp'


def fsync_folder(folder: str | Path) -> None:
    """Make a rename or a new name in `folder` durable (no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems refuse fsync on a folder; the rename itself stands
    finally:
        os.close(fd)


def remove_stale_temps(path: Path) -> list[Path]:
    """Delete temp files of `path` whose writing process is gone (a kill -9 leftover)."""
    removed = []
    prefix = _temp_prefix(path)
    for tmp in path.parent.glob(f'{prefix}*'):
        pid_text = tmp.name[len(prefix):].split('-', 1)[0]
        if pid_text.isdigit() and not _alive(int(pid_text)):
            tmp.unlink(missing_ok=True)
            removed.append(tmp)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    return True


def replace_text(path: str | Path, text: str) -> None:
    """Write a UTF-8 text file atomically."""
    with atomic_write(path, 'w', encoding='utf8') as handle:
        handle.write(text)
