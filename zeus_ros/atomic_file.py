"""Atomic file writes: a temp file beside the target, then one rename.

Readers never see half a file and a kill never leaves one (metadata.yaml, run state, CSV
tables, checkpoints). The temp name holds the process and thread, so two jobs writing the same
file at once (parallel evaluation splits) each rename a whole file of their own.
"""

from __future__ import annotations

from contextlib import contextmanager
import os
from pathlib import Path
import threading
from typing import IO, TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Iterator

__all__ = ['atomic_write', 'replace_text']


@contextmanager
def atomic_write(path: str | Path, mode: str = 'w', **open_args: Any) -> Iterator[IO[Any]]:
    """Open a temp file for writing; on a clean exit it replaces `path`, else it is removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f'.{path.name}.tmp{os.getpid()}-{threading.get_ident()}')
    try:
        with tmp.open(mode, **open_args) as handle:
            yield handle
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def replace_text(path: str | Path, text: str) -> None:
    """Write a UTF-8 text file atomically."""
    with atomic_write(path, 'w', encoding='utf8') as handle:
        handle.write(text)
