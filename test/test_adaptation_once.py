"""`zeus adaptation` on a zoo checkpoint measures it once, and its bars count passes (issue 52).

Before, `--checkpoint` the zoo file measured the same bytes twice ("yours" then "zoo"), the
progress bars restarting with nothing saying which pass ran. The measurement itself is faked:
what is checked is how often it runs and what the bars are called.
"""

from __future__ import annotations

from pathlib import Path
import shutil
from typing import Any

import pytest

from zeus_ros.cli import adaptation as cli
from zeus_ros.offline.evaluation import adaptation
from zeus_ros.system.launch_defaults import zoo_checkpoint


@pytest.fixture
def measured(monkeypatch: pytest.MonkeyPatch) -> list[tuple[Path, str]]:
    """Each measure_adaptation call's (checkpoint, label); the report is a blank one."""
    calls: list[tuple[Path, str]] = []

    def fake(checkpoint: Path, **kwargs: Any) -> adaptation.AdaptationReport:
        calls.append((Path(checkpoint), kwargs.get('label', '')))
        return adaptation.AdaptationReport(Path(checkpoint), 'Cheetah-Bias-v0', 'zeus')

    monkeypatch.setattr(adaptation, 'measure_adaptation', fake)
    return calls


def test_the_zoo_checkpoint_against_the_zoo_is_measured_once(
        measured: list[tuple[Path, str]], capsys: pytest.CaptureFixture[str]) -> None:
    """One measurement, one row 'yours = zoo', and a line saying why."""
    assert cli.main(['--checkpoint', str(zoo_checkpoint('Cheetah-Bias-v0')),
                     '--no-progress']) == 0
    out, err = capsys.readouterr()
    assert len(measured) == 1
    assert 'same sha256' in err and 'measured once' in err
    assert 'yours = zoo' in out


def test_a_copy_is_the_same_file_another_file_is_measured(
        tmp_path: Path, measured: list[tuple[Path, str]]) -> None:
    """Same bytes under another name: once; another checkpoint: both, each with its label."""
    copy = tmp_path / 'mine.pt'
    shutil.copy(zoo_checkpoint('Cheetah-Bias-v0'), copy)
    assert cli.main(['--checkpoint', str(copy), '--no-progress']) == 0
    assert len(measured) == 1
    measured.clear()
    other = zoo_checkpoint('Cheetah-Motor-v0')
    assert cli.main(['--checkpoint', str(copy), '--against', str(other), '--no-progress']) == 0
    assert [label for _, label in measured] == ['yours', str(other)]


def test_each_pass_names_its_number_out_of_all() -> None:
    """With a context: train values, then live and frozen per split, 'pass i/N' on each."""
    names = list(adaptation.pass_names(['interpolation', 'extrapolation'], True, 'yours'))
    assert names == ['yours pass 1/5: train values (mean context)',
                     'yours pass 2/5: interpolation live', 'yours pass 3/5: interpolation frozen',
                     'yours pass 4/5: extrapolation live', 'yours pass 5/5: extrapolation frozen']
    assert list(adaptation.pass_names(['interpolation'], False)) == [
        'pass 1/1: interpolation returns']
