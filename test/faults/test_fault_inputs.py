"""Fault matrix, bad-input rows: one line, exit 2, the flag or file named, nothing left behind.

No message may suggest `weights_only=False` (torch's own advice for a refused pickle).
"""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys
from typing import Any

import pytest
import torch

from zeus_ros.cli import collect, demo, launch, loop, train
from zeus_ros.learning.checkpoint import load_checkpoint
from zeus_ros.learning.errors import CheckpointError

from ros_harness import REPO

TASK = 'Cheetah-Run-v0'


class _Evil:
    """Unpickling this runs a shell command (what a malicious checkpoint would do)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, tuple[str]]:
        return os.system, (f'touch {self.marker}',)


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    """A malicious pickle, random bytes, a binary, an empty, a list and a broken YAML file."""
    made = {name: tmp_path / name for name in
            ('evil.pt', 'random.pt', 'binary.yaml', 'empty.yaml', 'list.yaml', 'broken.yaml')}
    torch.save({'format_version': 1, 'state': _Evil(tmp_path / 'pwned')}, made['evil.pt'])
    made['random.pt'].write_bytes(bytes(range(256)) * 8)
    made['binary.yaml'].write_bytes(b'\x93\x00\xff' * 100)
    made['empty.yaml'].write_text('# nothing but a comment\n')
    made['list.yaml'].write_text('- a\n- b\n')
    made['broken.yaml'].write_text('foo: [1, 2\n  bar: }}}\n')
    return made


def _one_line(capsys: Any, *needles: str) -> str:
    """The captured stderr: exactly one line, holding every needle, no traceback or advice."""
    err = capsys.readouterr().err
    assert err.count('\n') == 1, err
    assert 'Traceback' not in err and 'weights_only' not in err, err
    for needle in needles:
        assert needle in err, err
    return err


def test_malicious_pickle_is_refused_without_running_it_or_advising_weights_only(
        files: dict[str, Path]) -> None:
    """The refusal says what the file holds and never repeats torch's weights_only advice."""
    with pytest.raises(CheckpointError) as caught:
        load_checkpoint(files['evil.pt'])
    message = str(caught.value)
    assert 'GLOBAL' in message and 'never runs code' in message
    assert 'weights_only' not in message and 'trusted' not in message
    assert not (files['evil.pt'].parent / 'pwned').exists()


@pytest.mark.slow
def test_collect_bad_checkpoint_is_one_line_through_the_cli(files: dict[str, Path],
                                                            tmp_path: Path) -> None:
    """`zeus collect --checkpoint <pickle>` as a process: exit 2, one line, no bag folder."""
    result = subprocess.run(
        [sys.executable, '-m', 'zeus_ros.cli', 'collect', '--task', TASK, '--steps', '5',
         '--out', str(tmp_path / 'bags'), '--checkpoint', str(files['evil.pt']),
         '--no-progress'], cwd=REPO, capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 2, result.stderr
    assert result.stderr.count('\n') == 1 and 'Traceback' not in result.stderr
    assert result.stderr.startswith('zeus collect: --checkpoint: ')
    assert 'weights_only' not in result.stderr and str(files['evil.pt']) in result.stderr
    assert not (tmp_path / 'bags').exists() and not (tmp_path / 'pwned').exists()


def test_collect_random_bytes_and_bad_schedules(files: dict[str, Path], tmp_path: Path,
                                                capsys: Any) -> None:
    """A corrupt checkpoint and each kind of bad --schedule: exit 2, one line naming it."""
    out = tmp_path / 'bags'
    base = ['--task', TASK, '--steps', '5', '--out', str(out), '--no-progress']
    assert collect.main([*base, '--checkpoint', str(files['random.pt'])]) == 2
    _one_line(capsys, '--checkpoint', 'unreadable or corrupt')
    for schedule, needle in (('sideways', "kind 'sideways' is not known"),
                             ('switch:nope:every=10', "unknown preset split 'nope'"),
                             ('switch:train:every=x', 'every must be an integer'),
                             ('constant:value=banana', 'banana')):
        assert collect.main([*base, '--schedule', schedule]) == 2, schedule
        _one_line(capsys, f'--schedule {schedule}: ', needle)
    for name, needle in (('binary.yaml', 'is not a text file'),
                         ('broken.yaml', 'is not valid YAML at line 2, column 6'),
                         ('empty.yaml', 'must hold a mapping')):
        assert collect.main([*base, '--schedule', str(files[name])]) == 2, name
        _one_line(capsys, f'--schedule: {files[name]} ', needle)
    with pytest.raises(SystemExit) as exited:  # argparse checks --task: exit 2, one line
        collect.main([*base[:1], 'Nope-v0', *base[2:]])
    assert exited.value.code == 2
    _one_line(capsys, '--task', "unknown task 'Nope-v0'")
    assert not out.exists()


@pytest.mark.parametrize('name, needle', [
    ('binary.yaml', 'not a text file (byte 0x93 at offset 0'),
    ('empty.yaml', 'the file is empty (no keys); refusing'),
    ('list.yaml', 'expected a mapping of config keys, got a list'),
    ('broken.yaml', 'not valid YAML at line 2, column 6'),
])
def test_train_and_loop_refuse_a_bad_config(files: dict[str, Path], tmp_path: Path,
                                            capsys: Any, name: str, needle: str) -> None:
    """Binary, empty (no longer all defaults), non-mapping, broken: exit 2 before any output."""
    assert train.main(['--bags', str(tmp_path), '--config', str(files[name]), '--out',
                       str(tmp_path / 'run')]) == 2
    _one_line(capsys, f'zeus train: --config {files[name]}: ', needle)
    assert loop.main(['--task', TASK, '--config', str(files[name]), '--out',
                      str(tmp_path / 'loop')]) == 2
    _one_line(capsys, f'zeus loop: --config {files[name]}: ', needle)
    assert not (tmp_path / 'run').exists() and not (tmp_path / 'loop').exists()


@pytest.mark.skipif(torch.cuda.is_available(), reason='this torch has CUDA')
def test_device_cuda_without_cuda_is_one_line(tmp_path: Path, capsys: Any) -> None:
    """--device cuda on a CPU-only torch, and a device string torch cannot parse."""
    config = REPO / 'params' / 'train' / 'state_cpu.yaml'
    for device, needle in (('cuda', '--device cuda: this torch build has no CUDA support'),
                           ('cuda:1', '--device cuda:1: '), ('gpu7', "got 'gpu7'")):
        assert train.main(['--bags', str(tmp_path), '--config', str(config), '--out',
                           str(tmp_path / 'run'), '--device', device]) == 2
        _one_line(capsys, 'zeus train: ', needle)
    assert loop.main(['--task', TASK, '--config', str(config), '--out', str(tmp_path / 'loop'),
                      '--device', 'cuda']) == 2
    _one_line(capsys, 'zeus loop: --device cuda: ', 'use --device cpu or auto')
    assert not (tmp_path / 'run').exists() and not (tmp_path / 'loop').exists()
    shipped = REPO / 'checkpoints' / 'cheetah_run_v0_zeus_state.pt'
    with pytest.raises(CheckpointError, match="cannot load on device 'cuda': this torch build "
                       'has no CUDA support; use device cpu'):
        load_checkpoint(shipped, map_location='cuda')  # what a node with device: cuda does


@pytest.mark.parametrize('text, needle', [
    (b'\x93\x00\xff', 'not a text file'),
    (b'', 'the file is empty'),
    (b'foo: [1, 2\n  bar: }}}\n\t- x\n', 'not valid YAML at line 2'),
    (b'- a\n- b\n', 'expected node_name: ros__parameters'),
    (b'/**:\n  ros__parameters: [1, 2]\n', '/**: expected a ros__parameters: mapping'),
    (b'/**/policy:\n  ros__parameters:\n    noise: [1, a]\n', 'parameter noise: [1, '),
    (b'/**/policy:\n  ros__parameters:\n    noise:\n', 'parameter noise: None'),
    (b'/**/policy:\n  ros__parameters:\n    n:\n      deep: {}\n    m: [[1]]\n',
     'parameter m: [[1]]'),
])
def test_launch_refuses_a_garbage_params_file_before_starting_nodes(
        tmp_path: Path, capsys: Any, text: bytes, needle: str) -> None:
    """What rcl would refuse in every node (a traceback each) is one line from zeus launch."""
    params = tmp_path / 'params.yaml'
    params.write_bytes(text)
    assert launch.main(['--params', str(params), '--timeout', '1']) == 2
    _one_line(capsys, f'zeus launch: params file {params}: ', needle)


def test_demo_with_a_bad_checkpoint_leaves_no_results(files: dict[str, Path], tmp_path: Path,
                                                      capsys: Any) -> None:
    """Refused before any node starts: no steps.csv, no inspection.png, no --out at all."""
    out = tmp_path / 'demo'
    for name, needle in (('random.pt', 'unreadable or corrupt'), ('evil.pt', 'GLOBAL')):
        assert demo.main(['--checkpoint', str(files[name]), '--out', str(out),
                          '--steps', '5']) == 2
        _one_line(capsys, 'zeus demo: --checkpoint: ', needle)
    assert not out.exists()
