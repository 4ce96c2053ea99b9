"""`zeus report` of a continual run (offline/evaluation/continual_report.py), on real data.

A short real recording (MuJoCo, the zoo's Cheetah-Bias-v0 checkpoint, two splits of one run)
and a hand-written history with a refusal, a deployment, its swap and a rollback: the segments'
returns, every event on the run's time axis, the CSVs, the picture and the command line.
"""

from __future__ import annotations

import csv
import datetime
import itertools
import json
import math
from pathlib import Path
import shutil

from continual_fixtures import record
import pytest

from zeus_ros.cli import main as zeus
from zeus_ros.offline.evaluation import continual_report as cr
from zeus_ros.system.launch_defaults import zoo_checkpoint

BIAS = 'Cheetah-Bias-v0'
VALUES = [0.6, 0.8, 0.7, 0.9]
EVERY = 40
SPLIT_STEPS = 200


def _iso(epoch: float) -> str:
    return datetime.datetime.fromtimestamp(epoch, datetime.UTC).isoformat()


def _write_history(trainer: Path, recording: Path, first: float, last: float) -> None:
    """A deployment's history over the recording's wall-clock span [first, last]."""
    span = last - first

    def at(fraction: float) -> str:
        return _iso(first + fraction * span)

    lines = [
        {'time': _iso(first - 3.0), 'event': 'start', 'deployed': '/zoo/zeus.pt',
         'recording': str(recording)},
        {'time': at(0.1), 'event': 'round', 'round': 1, 'trigger': 'new steps',
         'new_splits': 1},
        {'time': at(0.25), 'event': 'gate', 'candidate': '/t/round_001/candidate.pt',
         'gain': 8.3, 'se': 6.2, 'required': 12.4, 'decision': 'refuse',
         'reason': 'gain +8.30 < 12.40', 'values': [], 'confirmation': None},
        {'time': at(0.26), 'event': 'chain', 'round': 1,
         'resume_from': '/t/round_001/candidate.pt'},
        {'time': at(0.4), 'event': 'round', 'round': 2, 'trigger': 'novelty alarm',
         'new_splits': 1},
        {'time': at(0.55), 'event': 'gate', 'candidate': '/t/round_002/candidate.pt',
         'gain': 15.0, 'se': 4.0, 'required': 8.0, 'decision': 'deploy',
         'reason': 'gain +15.00 >= 8.00 and no value worse than allowed', 'values': [],
         'confirmation': {'gain': 14.0, 'se': 4.5, 'deploy': True}},
        {'time': at(0.56), 'event': 'swap', 'round': 2,
         'checkpoint': '/t/deployed/round_002_abc.pt', 'sha256': 'abc', 'forced': False,
         'previous': '/zoo/zeus.pt', 'gate_gain': 15.0},
        {'time': at(0.8), 'event': 'live_check', 'checkpoint': '/t/deployed/round_002_abc.pt',
         'live_change': -30.5, 'allowed': 4.0, 'gate_gain': 15.0, 'decision': 'rollback',
         'rolled_back_to': '/zoo/zeus.pt', 'error': None},
        {'time': _iso(last + 5.0), 'event': 'stopped', 'round': 3,
         'progress': {'phase': 'training'}},
    ]
    trainer.mkdir(parents=True, exist_ok=True)
    (trainer / cr.HISTORY).write_text(''.join(json.dumps(line) + '\n' for line in lines))


@pytest.fixture(scope='module')
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """bags/continual_<date>/ (two closed splits of one run) and its _continual history."""
    recording = tmp_path_factory.mktemp('bags') / 'continual_20250101_120000'
    splits = record(recording, BIAS, VALUES, zoo_checkpoint(BIAS), splits=2,
                    steps=SPLIT_STEPS, every=EVERY, one_run=True)
    stamps = cr.step_stamps(splits)
    received = [t for t, _ in stamps]
    _write_history(recording.with_name(recording.name + cr.SUFFIX), recording,
                   min(received), max(received))
    return recording


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline='') as handle:
        return list(csv.DictReader(handle))


def test_either_folder_names_the_pair(tmp_path: Path) -> None:
    """The recording, its _continual folder, or a trainer folder set by `out` (start line)."""
    recording = tmp_path / 'bags' / 'continual_x'
    trainer = tmp_path / 'bags' / 'continual_x_continual'
    (recording / 'continual_x_000').mkdir(parents=True)
    (recording / 'continual_x_000' / 'metadata.yaml').write_text('{}\n')
    pair = cr.ContinualFolders(recording, trainer)
    assert cr.continual_folders(recording) == pair  # bag splits: a recording, history or not
    assert cr.continual_folders(trainer) == pair
    elsewhere = tmp_path / 'trainer_out'
    elsewhere.mkdir()
    (elsewhere / cr.HISTORY).write_text(json.dumps(
        {'time': '2025-01-01T12:00:00+00:00', 'event': 'start',
         'recording': str(recording)}) + '\n')
    assert cr.continual_folders(elsewhere) == cr.ContinualFolders(recording, elsewhere)
    assert cr.continual_folders(tmp_path) is None  # runs, sweeps: the training report's
    assert cr.continual_folders(tmp_path / 'nothing') is None


def test_a_folder_without_history_is_one_line_and_exit_2(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture
                                                         ) -> None:
    recording = tmp_path / 'continual_x'
    (recording / 'continual_x_000').mkdir(parents=True)
    (recording / 'continual_x_000' / 'metadata.yaml').write_text('{}\n')
    # A recording without history; a _continual folder that does not exist (refused while
    # the arguments are parsed, before anything is imported).
    for folder, why in ((recording, 'no continual history'),
                        (tmp_path / 'continual_x_continual', 'no such file or folder')):
        try:
            code = zeus(['report', str(folder)])
        except SystemExit as stop:
            code = stop.code
        assert code == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1, err
        assert err.startswith('zeus report: ') and why in err, err
    assert not (tmp_path / 'continual_x_continual').exists()  # nothing written


@pytest.mark.slow
def test_segments_and_every_decision_on_one_time_axis(run: Path, tmp_path: Path) -> None:
    out = tmp_path / 'out'
    report = cr.write_continual_report(run, out)
    assert report.task == BIAS and report.steps == 2 * SPLIT_STEPS and report.splits == 2
    assert report.episode_length == 40
    segments = _rows(out / 'continual_segments.csv')
    assert [int(s['segment']) for s in segments] == list(range(2 * SPLIT_STEPS // EVERY))
    assert [float(s['context']) for s in segments[:4]] == VALUES
    times = [float(s['t_s']) for s in segments]
    assert times == sorted(times) and times[0] < 1.0 and times[-1] < report.duration_s
    assert all(math.isfinite(float(s['return'])) and float(s['return']) < 0 for s in segments)
    assert {int(s['steps']) for s in segments} <= {EVERY - 1, EVERY}
    # the deployed checkpoint per segment: the zoo's, the swapped one, the zoo's again
    deployed = [name for name, _ in itertools.groupby(s['deployed'] for s in segments)]
    assert deployed == ['zeus.pt', 'round_002_abc.pt', 'zeus.pt'], deployed

    events = _rows(out / 'continual_events.csv')
    assert [e['event'] for e in events] == ['start', 'round', 'gate', 'chain', 'round', 'gate',
                                            'swap', 'live_check', 'stopped']
    at = [float(e['t_s']) for e in events]
    assert at == sorted(at)
    assert at[0] == 0.0 and at[-1] == pytest.approx(report.duration_s, abs=0.01)  # clamped
    assert all(0.0 < t < report.duration_s for t in at[1:-1])
    for event, fraction in zip(events[1:-1], (0.1, 0.25, 0.26, 0.4, 0.55, 0.56, 0.8),
                               strict=True):
        assert float(event['t_s']) == pytest.approx(fraction * report.duration_s, abs=0.1)
        assert float(event['outside_s']) == 0.0
    assert float(events[0]['outside_s']) == 3.0 and float(events[-1]['outside_s']) == 5.0
    assert events[3]['checkpoint'] == '/t/round_001/candidate.pt'
    refuse, deploy = events[2], events[5]
    assert (refuse['round'], refuse['decision'], float(refuse['gain']), float(refuse['se']),
            float(refuse['required'])) == ('1', 'refuse', 8.3, 6.2, 12.4)
    assert (deploy['round'], deploy['decision'], float(deploy['gain'])) == ('2', 'deploy', 15.0)
    rollback = events[7]
    assert rollback['decision'] == 'rollback' and float(rollback['gain']) == -30.5
    assert float(rollback['required']) == -4.0 and rollback['checkpoint'] == '/zoo/zeus.pt'
    assert events[8]['reason'] == 'stopped in training'
    assert (out / 'continual_returns.png').stat().st_size > 10_000

    assert report.counts == {'rounds': 2, 'deploys': 1, 'refusals': 1, 'swaps': 1,
                             'rollbacks': 1, 'failures': 0, 'stopped': 1}
    first, last = report.third(0), report.third(2)
    assert first[2] + report.third(1)[2] + last[2] == len(segments)
    text = report.summary()
    assert 'rounds 2' in text and 'swaps 1' in text and 'rollbacks 1' in text
    assert f'first third: {first[0]:.1f} ± {first[1]:.1f}' in text
    assert 'round 1 at' in text and 'refuse (gain +8.3 ± 6.2' in text


@pytest.mark.slow
def test_zeus_report_of_either_folder(run: Path, tmp_path: Path,
                                      capsys: pytest.CaptureFixture) -> None:
    trainer = run.with_name(run.name + cr.SUFFIX)
    assert zeus(['report', str(run)]) == 0  # default: into the _continual folder
    printed = capsys.readouterr().out
    assert 'gate decisions 1 deploy / 1 refuse' in printed and 'last third' in printed
    for name in cr.FILES:
        assert (trainer / name).stat().st_size > 0
    assert zeus(['report', '--folder', str(trainer), '--out', str(tmp_path / 'r')]) == 0
    assert capsys.readouterr().out.splitlines()[0] == printed.splitlines()[0]
    assert (tmp_path / 'r' / 'continual_events.csv').read_text() == \
        (trainer / 'continual_events.csv').read_text()
    copy = tmp_path / 'copy' / run.name  # the recording alone: no history beside it
    shutil.copytree(run, copy)
    assert zeus(['report', str(copy)]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and 'no continual history' in err, err


@pytest.mark.slow
def test_splits_whose_steps_start_over_are_refused(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture) -> None:
    """Two collections in one folder (steps from 0 in each): not one run's time axis."""
    recording = tmp_path / 'continual_y'
    record(recording, BIAS, VALUES[:2], zoo_checkpoint(BIAS), splits=2, steps=60, every=30)
    _write_history(recording.with_name(recording.name + cr.SUFFIX), recording, 0.0, 1.0)
    assert zeus(['report', str(recording)]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and 'steps start over' in err, err
