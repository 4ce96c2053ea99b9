"""experiments/heldout_distance.py re-measures by default; reuse only with --reuse (issue 52, 7).

Its rows are committed, and the printed command re-read them ("0 values measured"): a reader
believed they reproduced a number they had only re-printed. The measurement itself is replaced
by a stub here; what is checked is which values the script asks to be measured, and what it
says about it.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / 'experiments' / 'heldout_distance.py'
POINTS = [(-0.05, 0.1, 101), (0.1, 0.4, 102), (0.3, 0.6, 103)]


def _script(monkeypatch: pytest.MonkeyPatch, measured: list[float]) -> ModuleType:
    """The script with one fake checkpoint, three values, and a measure that records its calls."""
    spec = importlib.util.spec_from_file_location('heldout_distance', SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    def measure(task: str, method: str, seed: int, path: Path, points: list, episodes: int
                ) -> list[dict[str, Any]]:
        measured.extend(value for _d, value, _s in points)
        return [{'task': task, 'method': method, 'seed': seed, 'checkpoint': str(path),
                 'distance': d, 'value': v, 'env_seed': s, 'episodes': episodes,
                 'freeze': 'live', 'return': 1.0} for d, v, s in points]

    monkeypatch.setattr(module, 'checkpoints', lambda _task: [('zeus', 0, Path('z_s0.pt'))])
    monkeypatch.setattr(module, 'grid', lambda _task: POINTS)
    monkeypatch.setattr(module, 'measure', measure)
    monkeypatch.setattr(module, 'summary', lambda _rows: [])
    monkeypatch.setattr(module, 'plot', lambda *_args: None)
    return module


def test_a_rerun_measures_everything_unless_told_to_reuse(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    """Rows on disk: re-measured by default; --reuse keeps them; both runs say which it did."""
    argv = ['--task', 'Cheetah-Bias-v0', '--episodes', '2', '--out', str(tmp_path)]
    measured: list[float] = []
    _script(monkeypatch, measured).main(argv)
    assert measured == [0.1, 0.4, 0.6]
    assert '3 values measured, 0 reused' in capsys.readouterr().out

    measured.clear()  # the committed-rows case: the same command measures them all again
    _script(monkeypatch, measured).main(argv)
    assert measured == [0.1, 0.4, 0.6]
    assert '3 values measured, 0 reused' in capsys.readouterr().out

    measured.clear()
    _script(monkeypatch, measured).main([*argv, '--reuse'])
    assert measured == []
    out = capsys.readouterr().out
    assert '0 values measured, 3 reused' in out and '--reuse' in out
    runs = tmp_path / 'cheetah_bias_v0_50k_runs.csv'
    assert len(runs.read_text().splitlines()) == 1 + len(POINTS)  # replaced, not appended
