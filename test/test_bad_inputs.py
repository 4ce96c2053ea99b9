"""Issue 49 item 4: every bad input is one line on stderr and exit code 2, never a traceback.

The rows: `zeus export` / `zeus distill` / `zeus train` on a full disk (the write fails with
ENOSPC behind torch's RuntimeError, as on a real disk), network sizes beyond this machine's
memory, seeds beyond numpy's range, and a node process stopped while it is still importing.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any

import pytest

from zeus_ros.atomic_file import WRITE_FAULT_ENV, DiskFullError, atomic_write
from zeus_ros.cli import distill, export, train
from zeus_ros.learning.config import ZeusConfig, memory_limit
from zeus_ros.learning.errors import ConfigError
from zeus_ros.nodes.startup import started_as_node

from tiny_config import MINIMAL, write_config


def _torch_enospc(path: Path) -> RuntimeError:
    """What torch.save raises on a full disk: a RuntimeError whose context is the ENOSPC."""
    try:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    except OSError:
        try:
            raise RuntimeError('[enforce fail at inline_container.cc:603] . unexpected pos')
        except RuntimeError as error:
            return error


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert 'Traceback' not in err, err
    return lines[0]


def test_export_on_a_full_disk_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """The deployment file cannot be written: one line naming it, exit 2 (was 44-54 lines)."""
    checkpoint = tmp_path / 'run' / 'checkpoint.pt'
    checkpoint.parent.mkdir()
    checkpoint.write_bytes(b'x')
    out = tmp_path / 'deploy.pt'

    def full(*_args: Any, **_kwargs: Any) -> Any:
        raise _torch_enospc(out)

    monkeypatch.setattr(export, 'find_evaluations', lambda *_args: {})
    monkeypatch.setattr(export, 'export', full)
    code = export.main(['--checkpoint', str(checkpoint), '--out', str(out)])
    line = _one_line(capsys.readouterr().err)
    assert code == 2, line
    assert line.startswith(f'zeus export: no space left on the device writing {out}'), line
    assert 'free some space' in line, line


def test_distill_on_a_full_disk_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A round's file cannot be written: one line, exit 2; --resume only where it can resume."""
    out = tmp_path / 'student'

    def full(*_args: Any, **_kwargs: Any) -> Any:
        raise _torch_enospc(out / 'resume.pt')

    monkeypatch.setattr('zeus_ros.offline.training.distill.distill', full)
    (tmp_path / 'teacher.pt').write_bytes(b'x')  # the paths are checked before any work
    argv = ['--task', 'Cheetah-Run-v0', '--teacher', str(tmp_path / 'teacher.pt'),
            '--out', str(out), '--no-progress']
    code = distill.main(argv)
    line = _one_line(capsys.readouterr().err)
    assert code == 2, line
    assert line.startswith(f'zeus distill: no space left on the device writing {out}'), line
    assert 'nothing to resume' in line and '--resume' not in line, line
    out.mkdir()
    (out / 'resume.pt').write_bytes(b'x')
    assert distill.main(argv) == 2
    assert 'run it again with --resume' in _one_line(capsys.readouterr().err)


def test_train_on_a_full_disk_names_the_checkpoint_size_and_resumes_only_a_checkpoint(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The size is the whole file's, not the part that fit; no --resume without a checkpoint."""
    switch = tmp_path / 'write_fault'
    switch.write_text('ENOSPC')
    monkeypatch.setenv(WRITE_FAULT_ENV, str(switch))
    target = tmp_path / 'run' / 'checkpoint.pt'
    with pytest.raises(DiskFullError) as caught, atomic_write(target, 'wb', size=3 << 20) as f:
        f.write(b'part of it')  # what fitted before the disk filled
    assert 'needs about 3.0 MiB' in str(caught.value), caught.value

    out = tmp_path / 'run'

    def full(*_args: Any, **_kwargs: Any) -> None:
        raise DiskFullError(target, 3 << 20)

    monkeypatch.setattr('zeus_ros.offline.training.train.train', full)
    monkeypatch.setattr('zeus_ros.bags.recording.find_bags', lambda _folder: [])  # no bag needed
    monkeypatch.setattr('zeus_ros.bags.kinds.choose_bags', lambda bags, _kinds, _say: bags)
    config = write_config(tmp_path / 'minimal.yaml', MINIMAL)
    argv = ['--bags', str(tmp_path), '--config', str(config), '--out', str(out),
            '--no-progress', '--no-eval']
    assert train.main(argv) == 2
    line = _one_line(capsys.readouterr().err)
    assert 'needs about 3.0 MiB' in line and 'nothing to resume' in line, line
    assert '--resume' not in line, line
    target.write_bytes(b'an earlier checkpoint')
    assert train.main(argv) == 2
    assert f'--resume continues from {target}' in _one_line(capsys.readouterr().err)


def _zeus(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, '-m', 'zeus_ros.cli', *argv], capture_output=True,
                          text=True, cwd=cwd, timeout=300, check=False)


@pytest.mark.slow  # a subprocess that imports torch
def test_a_network_beyond_the_memory_is_one_line(tmp_path: Path) -> None:
    """hidden_dim: 2000000 (was a 30-line allocation traceback): key, estimate and limit."""
    config = write_config(tmp_path / 'huge.yaml', MINIMAL | {'hidden_dim': 2_000_000})
    done = _zeus('train', '--bags', str(tmp_path), '--config', str(config),
                 '--out', str(tmp_path / 'run'), '--no-progress', cwd=tmp_path)
    line = _one_line(done.stderr)
    assert done.returncode == 2, done.stderr
    assert 'hidden_dim=2000000' in line and 'TiB' in line, line
    assert 'use a smaller hidden_dim' in line, line
    print(line)


def test_the_memory_bound_keeps_the_shipped_sizes() -> None:
    """The defaults and pixel runs pass; a width whose estimate exceeds the memory does not."""
    ZeusConfig()
    ZeusConfig(obs_kind='pixels')
    limit = memory_limit()
    width = int((limit / 16 / 3) ** 0.5) + 1  # 3 h^2 trained (actor, 2 Q heads), 16 bytes each
    with pytest.raises(ConfigError, match='hidden_dim='):
        ZeusConfig(hidden_dim=width)


@pytest.mark.slow  # subprocesses that import torch
@pytest.mark.parametrize('command', ['train', 'collect'])
def test_a_seed_beyond_numpys_range_is_one_line(tmp_path: Path, command: str) -> None:
    """--seed 99999999999999999999 (was a 25-line numpy traceback): the range, exit 2."""
    extra = (['--bags', str(tmp_path), '--config', 'minimal.yaml'] if command == 'train'
             else ['--task', 'Cheetah-Run-v0', '--steps', '10'])
    done = _zeus(command, *extra, '--out', str(tmp_path / 'o'), '--seed',
                 '99999999999999999999', cwd=tmp_path)
    line = _one_line(done.stderr)
    assert done.returncode == 2, done.stderr
    assert '[0, 4294967295]' in line and '--seed' in line, line


def test_a_config_seed_beyond_numpys_range_is_refused() -> None:
    """The same bound in the config, for every command that reads one."""
    ZeusConfig(seed=2**32 - 1)
    for seed in (2**32, -1, 99999999999999999999):
        with pytest.raises(ConfigError, match=r'seed must be an integer in \[0, 4294967295\]'):
            ZeusConfig(seed=seed)


def test_only_a_node_process_stops_quietly_while_starting() -> None:
    """The quiet start-up stop is installed for node processes only, not for a CLI import."""
    assert started_as_node(['python', '-m', 'zeus_ros.nodes.policy_node'], '-m')
    script = '/x/lib/zeus_ros/policy_node'
    assert started_as_node(['python', script], script)
    assert not started_as_node(['python', '-m', 'pytest', 'test'], '-m')
    assert not started_as_node(['python', '/x/bin/zeus', 'launch'], '/x/bin/zeus')


@pytest.mark.slow  # a node process importing torch and rclpy
@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGTERM])
def test_a_node_stopped_while_importing_prints_no_traceback(stop: signal.Signals) -> None:
    """`zeus launch` stopping a policy that still imports: exit 0, nothing on stderr."""
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    env.setdefault('ROS_DOMAIN_ID', '97')
    process = subprocess.Popen([sys.executable, '-X', 'importtime', '-m',
                                'zeus_ros.nodes.policy_node'], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stderr is not None
    for line in process.stderr:  # -X importtime: a package's line comes after its __init__ ran
        if line.split('|')[-1].strip() == 'zeus_ros.nodes':
            break
    time.sleep(0.2)  # now inside the node module's imports (torch, rclpy take seconds)
    process.send_signal(stop)
    _out, err = process.communicate(timeout=60)
    err = '\n'.join(line for line in err.splitlines() if not line.startswith('import time:'))
    assert 'Traceback' not in err and 'KeyboardInterrupt' not in err, err
    assert process.returncode == 0, err
