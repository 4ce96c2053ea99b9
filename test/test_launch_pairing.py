"""`zeus launch` refuses another family's checkpoint before any node starts (issue 52, item 9).

Before, the bridge, estimator and policy all started and the agent nodes then exited 2 on the
task mismatch; now the launcher reads the checkpoint's task first and exits 2 with one line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from zeus_ros.cli import launch as launch_cli
from zeus_ros.learning.checkpoint import stored_task
from zeus_ros.learning.errors import CheckpointError
from zeus_ros.system.launch_defaults import zoo_checkpoint


def _no_start(*_args: Any, **_kwargs: Any) -> Any:
    raise AssertionError('a process was started')


def test_another_familys_checkpoint_is_one_line_exit_2_with_nothing_started(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """--task Cheetah-Motor-v0 with the Cheetah-Bias-v0 zoo checkpoint: refused, nothing run."""
    monkeypatch.setattr(launch_cli, 'plan_processes', _no_start)
    monkeypatch.setattr(launch_cli, 'run_group', _no_start)
    bias = zoo_checkpoint('Cheetah-Bias-v0')
    code = launch_cli.main(['--task', 'Cheetah-Motor-v0', '--checkpoint', str(bias),
                            '--no-progress'])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1, err
    assert "trained for 'Cheetah-Bias-v0'" in err and "'Cheetah-Motor-v0'" in err, err
    assert 'nothing started' in err


def test_the_params_files_task_is_checked_too(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """Without --task the default params file's task (Cheetah-Bias-v0) is the one checked."""
    monkeypatch.setattr(launch_cli, 'plan_processes', _no_start)
    monkeypatch.setattr(launch_cli, 'run_group', _no_start)
    motor = zoo_checkpoint('Cheetah-Motor-v0')
    assert launch_cli.main(['--checkpoint', str(motor), '--no-progress']) == 2
    assert "runs 'Cheetah-Bias-v0'" in capsys.readouterr().err


def test_a_matching_pair_goes_ahead(monkeypatch: pytest.MonkeyPatch) -> None:
    """The family's own checkpoint passes the check and the group is started."""
    started: list[Any] = []
    monkeypatch.setattr(launch_cli, 'run_group', lambda nodes, *a, **k: started.append(nodes) or 0)
    motor = zoo_checkpoint('Cheetah-Motor-v0')
    assert launch_cli.main(['--task', 'Cheetah-Motor-v0', '--checkpoint', str(motor),
                            '--no-progress']) == 0
    assert started and started[0]


def test_stored_task_reads_the_task_and_refuses_a_foreign_file(tmp_path: Path) -> None:
    """The cheap read names the zoo file's family; a file that is no checkpoint is one error."""
    assert stored_task(zoo_checkpoint('Cheetah-Motor-v0')) == 'Cheetah-Motor-v0'
    junk = tmp_path / 'junk.pt'
    junk.write_bytes(b'not a checkpoint')
    with pytest.raises(CheckpointError, match=r'junk\.pt'):
        stored_task(junk)
