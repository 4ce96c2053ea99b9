"""Continual rounds for a deployed pixel student (offline/training/continual_student.py).

A real pixel recording (frames and state vectors, as sim_bridge publishes and the recorder
records them), the zoo's teacher-head student and its teacher: the round trains and gates the
STATE teacher and deploys the refreshed student. Tiny budgets (about a minute on 2 cores,
most of it rendering the recording).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from zeus_ros.offline.training import continual as c
from zeus_ros.offline.training.continual_student import StudentError, state_teacher
from zeus_ros.system.continual_settings import ContinualSettings, read_history
from zeus_ros.system.launch_defaults import pixel_checkpoint, zoo_checkpoint

BIAS = 'Cheetah-Bias-v0'


@pytest.fixture(scope='module')
def pixel_recording(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two closed splits recorded by the pixel student acting on frames, beyond the range."""
    from zeus_ros.offline.training.collect_workers import CollectJob, collect_bag

    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp('pixrec') / 'run1'
    schedule = {'kind': 'switch', 'every': 40,
                'values': [{'motor_bias': 0.7}, {'motor_bias': 0.85}]}
    bags = [folder / f'run1_{i:03d}' for i in range(2)]
    for i, bag in enumerate(bags):
        collect_bag(CollectJob(BIAS, schedule, bag, 120, 10 + i,
                               checkpoint=pixel_checkpoint(BIAS), noise=0.2, pixels=True))
    return bags


@pytest.mark.slow
def test_a_pixel_recording_gives_the_state_teacher_its_state_vectors(
        pixel_recording: list[Path]) -> None:
    from zeus_ros.learning.checkpoint import load_checkpoint
    from zeus_ros.offline.data.ingest import ingest_bags
    from zeus_ros.offline.data.replay import ReplayBuffer

    dataset = ingest_bags(pixel_recording)
    assert dataset.has_frames  # the student's frames are there, and so are the state vectors
    teacher = load_checkpoint(zoo_checkpoint(BIAS), load_optimizers=False)
    assert all(ep.obs.shape[1:] == teacher.spec.obs_shape for ep in dataset.episodes)
    replay = ReplayBuffer(dataset, history=teacher.config.k, pixels=False, seed=0)
    batch = replay.sample(8)
    assert tuple(batch.obs.shape) == (8, *teacher.spec.obs_shape)


def test_the_state_teacher_of_a_student_is_found_or_refused_in_one_line(
        tmp_path: Path) -> None:
    from zeus_ros.learning.checkpoint import load_checkpoint, save_deployment

    student = pixel_checkpoint(BIAS)
    assert state_teacher(student) == zoo_checkpoint(BIAS).resolve()
    assert state_teacher(zoo_checkpoint(BIAS)) is None  # a state deployment: no student mode
    loaded = load_checkpoint(student, load_optimizers=False)
    gone = {**loaded.extra, 'distill': {**loaded.extra['distill'], 'teacher': 'gone/zeus.pt'}}
    lost = save_deployment(tmp_path / 'lost.pt', loaded.agent, step=loaded.step, extra=gone)
    with pytest.raises(StudentError, match=r'state teacher .* is not found; looked in') as info:
        state_teacher(lost)
    assert '\n' not in str(info.value)
    own = {**loaded.extra, 'distill': {**loaded.extra['distill'], 'settings': {
        **loaded.extra['distill']['settings'], 'head': 'own'}}}
    headed = save_deployment(tmp_path / 'own.pt', loaded.agent, step=loaded.step, extra=own)
    with pytest.raises(StudentError, match='not a teacher-head student'):
        state_teacher(headed)


@pytest.mark.slow
def test_a_student_round_trains_the_teacher_and_deploys_the_refreshed_student(
        pixel_recording: list[Path], tmp_path: Path) -> None:
    from zeus_ros.learning.checkpoint import load_checkpoint
    from zeus_ros.offline.data.ingest import ingest_bags

    student = pixel_checkpoint(BIAS)
    settings = ContinualSettings(warmup_updates=20, updates=30, episodes=1, max_seen_values=1,
                                 max_train_values=1, rehearsal_steps=200)
    history = tmp_path / 'history.jsonl'
    lines: list[str] = []
    answer = c.run_round(student, pixel_recording[1:], pixel_recording, tmp_path / 'round_001',
                         history, settings, first_checkpoint=student,
                         rehearsal_folder=tmp_path / 'rehearsal', forced=True, round_number=1,
                         log=lines.append)
    assert answer['teacher'] == str(zoo_checkpoint(BIAS).resolve())
    (rehearsal,) = (tmp_path / 'rehearsal').glob('*/bag_000')  # a state rehearsal, the teacher's
    assert not ingest_bags([rehearsal]).has_frames
    candidate = load_checkpoint(answer['teacher_candidate'], load_optimizers=False)
    assert candidate.config.obs_kind == 'state' and candidate.config.actor_gate > 0
    assert answer['candidate'] == str(tmp_path / 'round_001' / 'student.pt')
    deployed = load_checkpoint(answer['candidate'], load_optimizers=False)
    assert deployed.config.obs_kind == 'pixels'
    ours, theirs = (m.modules['actor'].state_dict() for m in (deployed.agent, candidate.agent))
    assert ours.keys() == theirs.keys()
    assert all(torch.equal(ours[k], theirs[k]) for k in ours)
    assert deployed.extra['refresh']['teacher_sha256'] == answer['teacher_sha256']
    (line,) = read_history(history)
    assert line['candidate'] == answer['teacher_candidate']  # gated: the state teacher's
    assert line['sha256'] == answer['teacher_sha256']
    assert line['deployed'] == answer['teacher'] and line['student'] == str(student)
    assert line['refreshed_student'] == answer['candidate']
    assert line['refreshed_sha256'] == answer['sha256'] and line['student_sha256']
    assert any('pixel student' in text for text in lines)
    # the trainer's swap: the student to OUT/deployed, its teacher beside it; found there
    # after the round folder is pruned (what a rollback or a restart deploys again)
    import shutil

    from zeus_ros.system.continual_settings import TEACHER_SUFFIX

    copy = tmp_path / 'deployed' / 'round_001_abc.pt'
    copy.parent.mkdir()
    shutil.copy2(answer['candidate'], copy)
    shutil.copy2(answer['teacher_candidate'], copy.with_name(copy.stem + TEACHER_SUFFIX))
    shutil.rmtree(tmp_path / 'round_001')
    assert state_teacher(copy) == copy.with_name(copy.stem + TEACHER_SUFFIX)


def test_continual_pixels_plan_deploys_the_student_and_the_trainer_retrains_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """`continual:=true obs:=pixels`: frames on, the zoo student on both agents and the trainer.

    `zeus launch` refuses, before anything starts, a pixel checkpoint the trainer cannot
    retrain (one line, exit 2).
    """
    from zeus_ros.cli import launch as launch_cli
    from zeus_ros.learning.checkpoint import load_checkpoint, save_deployment
    from zeus_ros.system import launch_defaults as d

    plan = d.plan_from_arguments({'continual': 'true', 'obs': 'pixels', 'task': BIAS})
    nodes = {node.name: node.parameters for node in plan.nodes}
    student = str(pixel_checkpoint(BIAS))
    assert nodes['sim_bridge']['pixels'] is True
    assert nodes[d.TRAINER]['checkpoint'] == nodes['policy']['checkpoint'] == student
    assert nodes['context_estimator']['checkpoint'] == student
    assert nodes[d.TRAINER]['recording'] == nodes['recorder']['output']
    assert nodes[d.TRAINER]['task'] == BIAS and nodes['policy']['noise'] == d.CONTINUAL_NOISE
    launch_cli._check_student(plan)  # its teacher is found: goes ahead

    def no_start(*_args: object, **_kwargs: object) -> None:
        raise AssertionError('a process was started')

    monkeypatch.setattr(launch_cli, 'plan_processes', no_start)
    monkeypatch.setattr(launch_cli, 'run_group', no_start)
    loaded = load_checkpoint(student, load_optimizers=False)
    gone = {**loaded.extra, 'distill': {**loaded.extra['distill'], 'teacher': 'gone/zeus.pt'}}
    lost = save_deployment(tmp_path / 'lost.pt', loaded.agent, step=loaded.step, extra=gone)
    code = launch_cli.main(['--continual', '--obs', 'pixels', '--task', BIAS,
                            '--checkpoint', str(lost), '--no-progress'])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert 'state teacher' in err and 'not found' in err
