"""Atomic file writes: a temp file beside the target, then one rename.

Readers never see half a file and a kill never leaves one (metadata.yaml, run state, CSV
tables, checkpoints). The temp name holds the process and thread, so two jobs writing the same
file at once (parallel evaluation splits) each rename a whole file of their own. The data are
fsynced before the rename and the folder after it, so a power cut leaves the old file or the
new one, never an empty name (a rename alone survives kill -9, not a lost page cache). Temp files
that a killed writer left beside the target are removed by the next write of that target.

A full disk (ENOSPC, EDQUOT) while writing is raised as `DiskFullError`: one line naming the
file, about how much it needed and what is free, the old file untouched. `$ZEUS_WRITE_FAULT`
names a switch file: while it exists, every atomic write and every bag flush fails with the
errno named in it (ENOSPC when empty), which is how the fault tests fill a disk where no small
file system can be mounted and deny a write to root (docs/faults.md).
"""

from __future__ import annotations

from contextlib import contextmanager
import errno
import os
from pathlib import Path
import threading
from typing import IO, TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Iterator

__all__ = [
    'WRITE_FAULT_ENV',
    'DiskFullError',
    'atomic_write',
    'disk_full',
    'disk_full_message',
    'free_space',
    'fsync_folder',
    'injected_write_fault',
    'remove_stale_temps',
    'replace_text',
    'size_text',
]

WRITE_FAULT_ENV = 'ZEUS_WRITE_FAULT'
"""Path of a switch file: while it exists, writes fail with the errno it names (fault tests)."""
FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})


@contextmanager
def atomic_write(path: str | Path, mode: str = 'w', *, size: int = 0,
                 **open_args: Any) -> Iterator[IO[Any]]:
    """Open a temp file for writing; on a clean exit it replaces `path`, else it is removed.

    `size`: the bytes the caller will write, where it knows them, so a full disk names what the
    whole file needs rather than the part of it that fit.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(path)
    tmp = path.with_name(f'{_temp_prefix(path)}{os.getpid()}-{threading.get_ident()}')
    try:
        with tmp.open(mode, **open_args) as handle:
            yield handle
            handle.flush()
            injected_write_fault(path)
            os.fsync(handle.fileno())
        tmp.replace(path)
        fsync_folder(path.parent)
    except Exception as error:
        full = disk_full(error)
        if full is None:
            raise
        raise DiskFullError(path, max(_size(tmp), size), full) from error
    finally:
        tmp.unlink(missing_ok=True)


class DiskFullError(OSError):
    """No space for a file: names it, roughly what it needed and what is free (one line)."""

    def __init__(self, path: Path, written: int, cause: OSError | None = None) -> None:
        self.path = Path(path)
        old = _size(self.path)
        # What failed to fit is at least what was written and at least the version it replaces.
        self.needed = max(written, old) + _BLOCK
        self.free = free_space(self.path.parent)
        kept = f'; the previous {self.path.name} is untouched' if old else ''
        super().__init__(errno.ENOSPC, f'no space left on the device writing {self.path}: it '
                         f'needs about {size_text(self.needed)}, {size_text(self.free)} free '
                         f'there{kept}')
        self.filename = str(self.path)
        self.cause = cause

    def __str__(self) -> str:
        return str(self.strerror)


def disk_full(error: BaseException) -> OSError | None:
    """The ENOSPC / EDQUOT OSError behind `error` (itself or what it was raised during)."""
    seen: BaseException | None = error
    for _ in range(8):  # torch raises a RuntimeError whose context is the ENOSPC
        if seen is None:
            return None
        if isinstance(seen, OSError) and seen.errno in FULL_ERRNOS:
            return seen
        seen = seen.__cause__ or seen.__context__
    return None


def disk_full_message(error: BaseException, where: str | Path) -> str | None:
    """One line for a full disk behind `error` (None for anything else); `where`: the output."""
    full = disk_full(error)
    if full is None:
        return None
    if isinstance(full, DiskFullError):
        return str(full)
    path = Path(full.filename or where)
    free = size_text(free_space(path.parent))
    return f'no space left on the device writing {path}: {free} free there'



def injected_write_fault(path: str | Path) -> None:
    """Raise the OSError `$ZEUS_WRITE_FAULT`'s switch file names while that file exists.

    Real code on the real write paths (atomic writes, bag flushes): a test fills the disk or
    denies the write by creating the file and clears the fault by removing it.
    """
    switch = os.environ.get(WRITE_FAULT_ENV)
    if not switch:
        return
    try:
        name = Path(switch).read_text().strip() or 'ENOSPC'
    except FileNotFoundError:
        return
    code = getattr(errno, name, errno.ENOSPC)
    raise OSError(code, f'{os.strerror(code)} ({WRITE_FAULT_ENV})', str(path))


_BLOCK = 4096


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def free_space(folder: Path) -> int:
    """Bytes free for us on the file system of `folder` (0 when it cannot be asked)."""
    import shutil

    try:
        return shutil.disk_usage(folder).free
    except OSError:
        return 0


def size_text(size: int) -> str:
    """A size for a message: KiB below 1 MiB, else MiB with one decimal."""
    return f'{size / 2**20:.1f} MiB' if size >= 2**20 else f'{max(1, size // 1024)} KiB'


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
