"""A disk that fills on demand, for the full-disk fault rows: a small tmpfs, or the injection.

Where this user may mount (root), a real tmpfs; elsewhere $ZEUS_WRITE_FAULT's switch file makes
the project's write paths fail the same way (zeus_ros.atomic_file.injected_write_fault).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
import os
from pathlib import Path
import shutil
import subprocess

from zeus_ros.atomic_file import WRITE_FAULT_ENV

__all__ = ['SmallDisk', 'mount_tmpfs']


@dataclass
class SmallDisk:
    """A folder whose file system can be filled (`fill`) and freed (`free`) during a test."""

    root: Path
    mounted: bool
    switch: Path

    def fill(self) -> None:
        """Leave about 4 KiB free: a filler file on the tmpfs, or the injection's switch."""
        if self.mounted:  # in chunks: a writer beside it (a recorder) fills it too
            chunk = b'\0' * 65536
            with contextlib.suppress(OSError), (self.root / 'filler').open('wb') as handle:
                while shutil.disk_usage(self.root).free > 4096 + len(chunk):
                    handle.write(chunk)
                    handle.flush()
                handle.write(b'\0' * max(0, shutil.disk_usage(self.root).free - 4096))
        else:
            self.switch.write_text('ENOSPC')

    def free(self) -> None:
        """Give the space back."""
        (self.root / 'filler').unlink(missing_ok=True)
        self.switch.unlink(missing_ok=True)

    @property
    def how(self) -> str:
        """What stands in for the full disk, for the test's report line."""
        if self.mounted:
            return 'a tmpfs filled by a file'
        return f'{WRITE_FAULT_ENV} (no mount allowed)'


def mount_tmpfs(folder: Path, size: str) -> bool:
    """Mount a tmpfs of `size` on `folder`; False where this user may not."""
    if os.geteuid() != 0 or shutil.which('mount') is None:
        return False
    done = subprocess.run(['mount', '-t', 'tmpfs', '-o', f'size={size}', 'tmpfs', str(folder)],
                          capture_output=True, check=False)
    return done.returncode == 0
