"""Fault matrix, full-disk rows: `zeus train` and `zeus collect` on a disk that fills up.

The disk is a real small file system (a tmpfs mounted for the test) where this user may mount
one (root, as on the development machine); elsewhere the same rows run on the write-failure
injection ($ZEUS_WRITE_FAULT, real code on the write paths: atomic_file.injected_write_fault).
Each row: one line naming the path and the space needed, exit code 2, nothing half written,
the old checkpoint byte for byte the same.
"""

from __future__ import annotations

from collections.abc import Iterator
import hashlib
from pathlib import Path
import subprocess

import pytest
from small_disk import SmallDisk, mount_tmpfs

from zeus_ros.atomic_file import WRITE_FAULT_ENV
from zeus_ros.cli import collect, train

from tiny_config import MINIMAL, write_config

TASK = 'Cheetah-Run-v0'

pytestmark = pytest.mark.slow  # MuJoCo episodes and training


@pytest.fixture
def small_disk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[SmallDisk]:
    """A 2 MiB file system at tmp/disk (or the injection, armed by `fill`)."""
    root = tmp_path / 'disk'
    root.mkdir()
    switch = tmp_path / 'write_fault'
    monkeypatch.setenv(WRITE_FAULT_ENV, str(switch))
    mounted = mount_tmpfs(root, '2m')
    try:
        yield SmallDisk(root, mounted, switch)
    finally:
        if mounted:
            subprocess.run(['umount', '-l', str(root)], check=False)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """200 steps of the task, collected once for this module."""
    out = tmp_path_factory.mktemp('bags')
    assert collect.main(['--task', TASK, '--steps', '200', '--out', str(out),
                         '--no-progress']) == 0
    return out / 'bag_000'


def test_train_on_a_full_disk_is_one_line_and_keeps_the_old_checkpoint(
        small_disk: SmallDisk, bag: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Train, fill the disk, resume: exit 2, one line with the path and the space needed."""
    config = write_config(tmp_path / 'minimal.yaml', MINIMAL)
    out = small_disk.root / 'run'
    argv = ['--bags', str(bag), '--config', str(config), '--out', str(out), '--no-progress',
            '--no-eval']
    assert train.main(argv) == 0
    checkpoint = out / 'checkpoint.pt'
    before = _sha(checkpoint)
    capsys.readouterr()
    small_disk.fill()
    code = train.main([*argv, '--resume', '--updates', '12'])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert f'no space left on the device writing {out}/' in lines[0], err
    assert 'needs about' in lines[0] and 'free there' in lines[0], err
    assert _sha(checkpoint) == before  # the old checkpoint survives, byte for byte
    assert not [p.name for p in out.iterdir() if '.tmp' in p.name]  # no half-written file
    print(f'train on a full disk ({small_disk.how}): {lines[0]}')


@pytest.mark.parametrize('workers', ['1', pytest.param('2', marks=pytest.mark.faults_only)])
def test_collect_on_a_full_disk_is_one_line_and_leaves_no_half_bag(
        small_disk: SmallDisk, workers: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Collect more than fits: exit 2, one line with the steps' size, the partial bags removed.

    With 2 workers (make faults: two spawned processes take ~10 s) the line comes from a
    worker process, as one line too.
    """
    out = small_disk.root / 'bags'
    if small_disk.mounted:  # 8,000 steps take ~3.2 MiB: the 2 MiB tmpfs fills on the way
        steps = '8000'
    else:  # the injection refuses the bag at once
        steps = '200'
        small_disk.fill()
    code = collect.main(['--task', TASK, '--steps', steps, '--out', str(out), '--no-progress',
                         '--workers', workers])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    assert f'no space left on the device writing {out}/bag_00' in err, err
    assert 'the half-written bag is removed' in err, err
    if small_disk.mounted:
        assert f'{int(steps) // int(workers)} steps need about' in err, err
    assert not list(out.iterdir())
    print(f'collect on a full disk ({small_disk.how}): {err}')
