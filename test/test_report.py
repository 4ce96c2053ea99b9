"""`zeus report` over an experiment folder laid out as experiments/run_one.sh writes it."""

from __future__ import annotations

from pathlib import Path

import pytest

from zeus_ros.cli.report import main
from zeus_ros.offline.evaluation.metrics import read_csv, write_csv
from zeus_ros.offline.evaluation.report import per_method, per_run, wall_time_table
from zeus_ros.offline.runs import mark_evaluated, mark_trained, read_state


def _run(folder: Path, name: str, returns: dict[str, float], *, train: int,
         earlier: int | None = None) -> None:
    """One finished run: eval_<split>/summary.csv + .done markers with wall seconds."""
    run = folder / name
    run.mkdir(parents=True)
    (run / '.done_train').write_text(f'{train}\n')
    if earlier is not None:
        (run / '.done_train_first').write_text(f'{earlier}\n')
    for split, value in returns.items():
        write_csv(run / f'eval_{split}' / 'summary.csv', [
            {'policy': 'agent', 'split': split, 'mean_return': value,
             'switching_return': value - 1, 'mean_latency': 12, 'spearman': 0.5},
            {'policy': 'random', 'split': split, 'mean_return': 20.0}])
        (run / f'eval_{split}' / '.done').write_text('7\n')


def test_report_means_standard_errors_and_wall_times(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture) -> None:
    """Mean ± s.e. over seeds, unfinished evals left out, resumed runs show both pieces."""
    folder = tmp_path / 'exp'
    _run(folder, 'zeus_s0', {'train': 100.0, 'extrapolation': 50.0}, train=300, earlier=400)
    _run(folder, 'zeus_s1', {'train': 200.0, 'extrapolation': 70.0}, train=310)
    _run(folder, 'no_context_s0', {'train': 90.0}, train=120)
    (folder / 'no_context_s0' / 'eval_train' / '.done').unlink()  # still running: left out

    rows = per_method(folder)
    assert [(r['method'], r['split'], r['seeds']) for r in rows] == [
        ('zeus', 'train', 2), ('zeus', 'extrapolation', 2)]
    assert rows[0]['mean_return'] == pytest.approx(150.0)
    assert rows[0]['mean_return_se'] == pytest.approx(50.0)  # std(ddof=1) / sqrt(2)

    out = tmp_path / 'report'
    assert main([str(folder), '--out', str(out)]) == 0
    assert '| zeus | train | 2 | 150.0 ± 50.0 |' in capsys.readouterr().out
    runs = read_csv(out / 'runs.csv')
    assert {(r['seed'], r['split'], r['train_seconds']) for r in runs} == {
        (0, 'train', 300), (0, 'extrapolation', 300), (1, 'train', 310),
        (1, 'extrapolation', 310)}
    table = (out / 'wall_times.md').read_text()
    assert '| zeus | (400 + 300) + 14 | 310 + 14 |' in table
    assert table == wall_time_table(runs) + '\n'
    assert (out / 'returns.png').stat().st_size > 0


def test_report_on_a_folder_without_evaluations_fails_clearly(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture
                                                              ) -> None:
    """No finished evaluation: exit 2 and a message naming the folder and the layout."""
    assert main([str(tmp_path), '--out', str(tmp_path / 'out')]) == 2
    assert 'no finished evaluations' in capsys.readouterr().err


def test_runs_recorded_in_state_json_and_old_markers_report_alike(tmp_path: Path) -> None:
    """A new run's state.json and an old run's .done markers give the same report rows."""
    folder = tmp_path / 'exp'
    _run(folder, 'zeus_s0', {'train': 100.0}, train=300)  # old layout: markers
    new = folder / 'zeus_s1'
    _run(folder, 'zeus_s1', {'train': 200.0, 'extrapolation': 70.0}, train=0)
    for marker in (new / '.done_train', *new.glob('eval_*/.done')):
        marker.unlink()  # a new run keeps no markers: only state.json says what finished
    assert read_state(new).evaluated == {} and not read_state(new).trained
    mark_trained(new, 310.04)
    mark_evaluated(new, 'train', 7.0)
    assert read_state(new).done(['train']) and not read_state(new).done(['train',
                                                                        'extrapolation'])
    rows = per_run(folder)  # extrapolation of zeus_s1 is not finished: left out
    assert [(r['seed'], r['split'], r['train_seconds'], r['eval_seconds']) for r in rows] == [
        (0, 'train', '300', '7'), (1, 'train', '310', '7')]
    mark_evaluated(new, 'extrapolation', 9.5)
    assert [r['eval_seconds'] for r in per_run(folder)][-1] == '9.5'
    assert [p.name for p in new.iterdir() if p.is_file()] == ['state.json']


def test_parallel_evaluations_of_one_run_all_land_in_its_state(tmp_path: Path) -> None:
    """Splits finishing at once in worker processes (zeus eval --jobs) are all recorded."""
    from concurrent.futures import ProcessPoolExecutor

    splits = [f'split{i}' for i in range(8)]
    with ProcessPoolExecutor(4) as pool:
        list(pool.map(mark_evaluated, [tmp_path] * len(splits), splits, range(len(splits))))
    assert read_state(tmp_path).evaluated == {s: float(i) for i, s in enumerate(splits)}


def test_an_unreadable_state_file_is_one_clear_error(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    """A truncated state.json names the file and what to do, instead of a JSON traceback."""
    _run(tmp_path / 'exp', 'zeus_s0', {'train': 1.0}, train=3)
    (tmp_path / 'exp' / 'zeus_s0' / 'state.json').write_text('{"train": ')
    with pytest.raises(ValueError, match=r'state.json: unreadable run state .* delete it'):
        read_state(tmp_path / 'exp' / 'zeus_s0')
    assert main(['--folder', str(tmp_path / 'exp'), '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and 'zeus_s0/state.json: unreadable run state' in err


@pytest.mark.slow
def test_the_scripts_state_command_line_reads_old_markers_and_continued_runs(
        tmp_path: Path) -> None:
    """`python -m zeus_ros.cli.run_state` as experiments/run_one.sh and run_queue.sh call it."""
    import subprocess
    import sys

    def state(*args: object) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, '-m', 'zeus_ros.cli.run_state',
                               *map(str, args)], capture_output=True, text=True, check=False,
                              timeout=60)

    _run(tmp_path, 'old_s0', {'train': 1.0}, train=156)  # finished under the old markers
    old = tmp_path / 'old_s0'
    assert state('done', old).returncode == 0 and state('done', old, 'train').returncode == 0
    assert state('done', old, 'extrapolation').returncode == 1
    assert state('seconds', old).stdout == '156\n'
    longer = tmp_path / 'longer_s0'  # a longer run continuing old_s0: not trained until marked
    assert state('mark-continued', longer, 156).returncode == 0
    assert state('done', longer).returncode == 1 and state('seconds', longer).stdout == '\n'
    assert state('mark-trained', longer, 400).returncode == 0
    assert state('mark-evaluated', longer, 'train', 12).returncode == 0
    assert state('done', longer, 'train').returncode == 0
    assert (read_state(longer).train_seconds, read_state(longer).earlier_train_seconds) == (
        400.0, 156.0)
    (longer / 'state.json').write_text('{"train": ')
    broken = state('done', longer)
    assert broken.returncode == 2 and len(broken.stderr.splitlines()) == 1
    assert 'state.json: unreadable run state' in broken.stderr
