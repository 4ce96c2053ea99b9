"""zeus_ros.atomic_file: the one atomic write (metadata.yaml, run state, tables, checkpoints)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
import os
from pathlib import Path

import pytest

from zeus_ros.atomic_file import atomic_write, replace_text


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temp(tmp_path: Path) -> None:
    target = tmp_path / 'table.csv'
    replace_text(target, 'old\n')
    with pytest.raises(RuntimeError), atomic_write(target) as handle:
        handle.write('half of the new')
        raise RuntimeError('killed mid-write')
    assert target.read_text() == 'old\n'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['table.csv']


def test_concurrent_writers_of_one_file_each_replace_it_whole(tmp_path: Path) -> None:
    """Two evaluation jobs may store the same file at once: the result is one writer's text."""
    target = tmp_path / 'sub' / 'train_mean_context.json'
    texts = [str(i) * 100_000 for i in range(8)]
    with ThreadPoolExecutor(8) as pool:
        list(pool.map(lambda text: replace_text(target, text), texts))
    assert target.read_text() in texts
    assert sorted(p.name for p in target.parent.iterdir()) == ['train_mean_context.json']


def test_a_killed_writers_temp_file_is_removed_by_the_next_write(tmp_path: Path) -> None:
    """Kill -9 mid-write leaves `.name.tmp<pid>-<thread>`; the next write of the file clears it."""
    import subprocess
    import sys

    target = tmp_path / 'checkpoint.pt'
    code = ('import os, sys; from zeus_ros.atomic_file import atomic_write\n'
            'with atomic_write(sys.argv[1], "wb") as h:\n'
            '    h.write(b"x" * 1000); h.flush(); print("writing", flush=True)\n'
            '    os.kill(os.getpid(), 9)')
    done = subprocess.run([sys.executable, '-c', code, str(target)], capture_output=True,
                          text=True, timeout=60, check=False)
    assert done.returncode == -9 and 'writing' in done.stdout
    leftovers = [p for p in tmp_path.iterdir() if p.name.startswith('.checkpoint.pt.tmp')]
    assert len(leftovers) == 1 and not target.exists()
    live_writer = tmp_path / f'.checkpoint.pt.tmp{os.getpid()}-1'  # ours: still running
    live_writer.write_bytes(b'busy')
    replace_text(target, 'new')
    assert sorted(p.name for p in tmp_path.iterdir()) == [live_writer.name, 'checkpoint.pt']


def test_the_data_and_the_folder_are_synced_around_the_rename(tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch
                                                               ) -> None:
    """Fsync of the temp file before the rename, of the folder after it."""
    import stat

    calls: list[str] = []
    real = os.fsync

    def record(fd: int) -> None:
        kind = 'folder' if stat.S_ISDIR(os.fstat(fd).st_mode) else 'file'
        calls.append(f'{kind}:{(tmp_path / "t.csv").exists()}')
        real(fd)

    monkeypatch.setattr(os, 'fsync', record)
    replace_text(tmp_path / 't.csv', 'a,b\n')
    assert calls == ['file:False', 'folder:True']
