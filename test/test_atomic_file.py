"""zeus_ros.atomic_file: the one atomic write (metadata.yaml, run state, tables, checkpoints)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
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
