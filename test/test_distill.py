"""`zeus distill`: a pixel student learns from the zoo's state teacher (real renders, tiny)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from zeus_ros.cli.distill import main
from zeus_ros.learning.config import load_config
from zeus_ros.learning.errors import ConfigError
from zeus_ros.learning.frames import FrameStack
from zeus_ros.learning.inference import InferenceAgent
from zeus_ros.offline.rollout import parse_schedule
from zeus_ros.offline.training.distill import (
    SCHEDULE,
    distill_loss,
    make_student,
    random_shift,
)
from zeus_ros.offline.training.distill_data import Episode, EpisodeStore, collect_round

torch.set_num_threads(1)
REPO = Path(__file__).resolve().parents[1]
TEACHER = REPO / 'checkpoints' / 'cheetah_bias_v0' / 'zeus.pt'
TASK = 'Cheetah-Bias-v0'
TINY = {'method': 'zeus_no_context_loss', 'obs_kind': 'pixels', 'k': 10, 'context_dim': 10,
        'transition_dim': 8, 'context_hidden_dim': 16, 'feature_dim': 8, 'num_conv_layers': 1,
        'num_filters': 4, 'hidden_dim': 32, 'model_hidden_dim': 16, 'batch_size': 16,
        'device': 'cpu', 'seed': 0}


@pytest.fixture(scope='module')
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('distill') / 'tiny.yaml'
    path.write_text(yaml.safe_dump(TINY))
    return path


@pytest.mark.slow
def test_a_tiny_run_writes_a_student_that_acts_from_frames(tiny: Path, tmp_path: Path) -> None:
    """Round 0 (teacher acts) + round 1 (student acts): a deployable pixel checkpoint."""
    out = tmp_path / 'run'
    code = main(['--task', TASK, '--teacher', str(TEACHER), '--config', str(tiny),
                 '--out', str(out), '--rounds', '2', '--first-steps', '45',
                 '--round-steps', '42', '--updates', '2', '--window', '8', '--no-progress'])
    assert code == 0
    agent = InferenceAgent.from_checkpoint(out / 'student.pt', expect_task=TASK,
                                           expect_obs_kind='pixels')
    assert agent.context_dim == 10 and agent.k == 10
    frames = FrameStack()
    history = agent.new_history()
    rng = np.random.default_rng(0)
    obs = frames.reset(rng.integers(0, 255, (84, 84, 3), dtype=np.uint8))
    for _ in range(3):
        action = agent.act(obs, agent.context(history))
        nxt = frames.push(rng.integers(0, 255, (84, 84, 3), dtype=np.uint8))
        history.push(obs, action, 0.0, nxt)
        obs = nxt
    assert action.shape == (6,) and np.isfinite(action).all()
    rounds = (out / 'rounds.csv').read_text().splitlines()
    assert rounds[1].split(',')[1] == 'teacher' and rounds[2].split(',')[1] == 'student'


class _Spy(InferenceAgent):
    """Records every action it returns."""

    def __init__(self, agent: InferenceAgent) -> None:
        super().__init__(agent.agent)
        self.actions: list[np.ndarray] = []

    def act(self, *args: object, **kwargs: object) -> np.ndarray:
        action = super().act(*args, **kwargs)
        self.actions.append(action)
        return action


@pytest.mark.slow
def test_in_a_dagger_round_the_student_acts_and_the_teacher_labels(tiny: Path) -> None:
    """The env applies the student's actions; every step carries the teacher's own action/psi."""
    teacher = _Spy(InferenceAgent.from_checkpoint(TEACHER))
    student = _Spy(InferenceAgent(make_student(load_config(tiny), teacher, TASK)))
    episodes, returns = collect_round(TASK, parse_schedule(SCHEDULE), teacher, student, 42,
                                      seed=3, noise=0.0, progress=False)
    assert len(episodes) == 1 and len(returns) == 1
    ep = episodes[0]
    n = len(ep)
    assert ep.frames.shape == (n, 3, 84, 84) and ep.frames.dtype == np.uint8
    np.testing.assert_allclose(ep.applied[1:], np.stack(student.actions[:n - 1]), atol=1e-6)
    np.testing.assert_allclose(ep.teacher_action, np.stack(teacher.actions[:n]), atol=1e-6)
    assert not np.allclose(ep.teacher_action[:n - 1], ep.applied[1:], atol=1e-2)
    assert ep.teacher_psi.shape == (n, 10) and np.isfinite(ep.teacher_psi).all()


@pytest.mark.slow
def test_the_losses_fall_on_a_fixed_synthetic_batch(tiny: Path) -> None:
    """Action + psi regression through conv phi and psi learns (random frames, fixed labels)."""
    teacher = InferenceAgent.from_checkpoint(TEACHER)
    student = make_student(load_config(tiny), teacher, TASK)
    rng = np.random.default_rng(0)
    store = EpisodeStore(1000)
    store.add(Episode(frames=rng.integers(0, 255, (20, 3, 84, 84), dtype=np.uint8),
                      applied=rng.uniform(-1, 1, (20, 6)).astype(np.float32),
                      reward=rng.standard_normal(20).astype(np.float32),
                      teacher_action=rng.uniform(-0.8, 0.8, (20, 6)).astype(np.float32),
                      teacher_psi=rng.standard_normal((20, 10)).astype(np.float32),
                      context=np.zeros((20, 1)), state=np.zeros((20, 0), np.float32)))
    batch = store.sample(rng, 2, 8, 10)
    assert batch.stacks.shape == (2, 18, 9, 84, 84)
    assert random_shift(batch.stacks, 4, rng).shape == batch.stacks.shape
    params = [p for name in ('encoder', 'psi', 'actor')
              for p in student.modules[name].parameters()]
    optimizer = torch.optim.Adam(params, lr=3e-3)
    scale = torch.from_numpy(store.psi_scale())
    losses = []
    for _ in range(60):
        loss, metrics = distill_loss(student, batch, 10, scale, 1.0)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    assert {'loss/action', 'loss/psi'} <= set(metrics)
    assert losses[-1] < 0.75 * losses[0], losses[::10]


@pytest.mark.parametrize(('args', 'message'), [
    (['--teacher', str(REPO / 'checkpoints' / 'cheetah_motor_v0' / 'zeus.pt')],
     "trained on 'Cheetah-Motor-v0', not 'Cheetah-Bias-v0'"),
    (['--teacher', str(TEACHER), '--config', str(REPO / 'params' / 'train' / 'state_cpu.yaml')],
     "obs_kind 'state'"),
    (['--teacher', str(REPO / 'nowhere.pt')], 'no such file'),
    (['--teacher', str(TEACHER), '--head', 'mine'], 'head must be one of own, teacher'),
    (['--teacher', str(TEACHER), '--head', 'teacher', '--no-context'],
     'cannot be a no_context student'),
    (['--teacher', str(TEACHER), '--resume'], 'holds no stopped run (resume.pt is missing)'),
])
def test_bad_input_is_one_clear_line(args: list[str], message: str, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    """A teacher of another task, a state config, a missing file: exit 2, one line, no run."""
    try:
        code = main(['--task', TASK, '--out', str(tmp_path / 'run'), '--no-progress', *args])
    except SystemExit as stop:  # a missing path is refused while parsing, before torch loads
        code = stop.code
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert message in err and len(err.splitlines()) == 1
    assert not (tmp_path / 'run' / 'student.pt').exists()


def test_the_context_sensitivity_of_a_pixel_agent_is_not_measured_from_states(
        tiny: Path) -> None:
    """`zeus adaptation` on a student: the traces hold states, so NaN instead of a crash."""
    from zeus_ros.offline.evaluation.diagnostics import context_sensitivity

    teacher = InferenceAgent.from_checkpoint(TEACHER)
    student = InferenceAgent(make_student(load_config(tiny), teacher, TASK))
    values = [{'motor_bias': -0.3}, {'motor_bias': 0.3}]
    assert np.isnan(context_sensitivity(student, [], values))


@pytest.mark.slow
def test_the_teacher_head_trains_phi_only_under_the_teachers_frozen_psi_and_actor(
        tiny: Path) -> None:
    """Head 'teacher': psi and actor are the teacher's and stay so; phi(o) learns phi_T(s)."""
    teacher = InferenceAgent.from_checkpoint(TEACHER)
    student = make_student(load_config(tiny), teacher, TASK, head='teacher')
    assert student.config.feature_dim == teacher.agent.config.feature_dim
    for name in ('psi', 'actor'):
        mine, theirs = student.modules[name].state_dict(), teacher.agent.modules[name].state_dict()
        assert all(torch.equal(mine[key], theirs[key]) for key in theirs)
        assert not any(p.requires_grad for p in student.modules[name].parameters())
    with pytest.raises(ConfigError, match='cannot be a no_context student'):
        make_student(load_config(tiny), teacher, TASK, head='teacher', no_context=True)

    rng = np.random.default_rng(1)
    n = 24
    state = rng.standard_normal((n, 17)).astype(np.float32)
    store = EpisodeStore(1000)
    store.add(Episode(frames=rng.integers(0, 255, (n, 3, 84, 84), dtype=np.uint8),
                      applied=rng.uniform(-1, 1, (n, 6)).astype(np.float32),
                      reward=rng.standard_normal(n).astype(np.float32),
                      teacher_action=rng.uniform(-0.8, 0.8, (n, 6)).astype(np.float32),
                      teacher_psi=rng.standard_normal((n, 10)).astype(np.float32),
                      context=np.zeros((n, 1)), state=state))
    batch = store.sample(rng, 2, 8, 10)
    assert batch.state.shape == (2, 18, 17)
    with torch.no_grad():
        target = teacher.agent.modules['encoder'](batch.state.flatten(0, 1)).view(2, 18, -1)
    optimizer = torch.optim.Adam(student.modules['encoder'].parameters(), lr=3e-3)
    frozen = {k: v.clone() for k, v in student.modules['actor'].state_dict().items()}
    scale = torch.from_numpy(store.psi_scale())
    losses = []
    for _ in range(40):
        loss, metrics = distill_loss(student, batch, 10, scale, 1.0, target, 1.0)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(metrics['loss/feature'])
    assert losses[-1] < 0.5 * losses[0], losses[::10]
    assert all(torch.equal(v, frozen[k]) for k, v in student.modules['actor'].state_dict().items())


@pytest.mark.slow
def test_a_round_zero_cache_without_states_is_refused_by_the_teacher_head(
        tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Data saved before states were stored loads for the own head, and is named otherwise."""
    rng = np.random.default_rng(0)
    n = 41
    cache = tmp_path / 'round0.npz'
    np.savez(cache, lengths=np.array([n]),
             frames=rng.integers(0, 255, (n, 3, 84, 84), dtype=np.uint8),
             applied=np.zeros((n, 6), np.float32), reward=np.zeros(n, np.float32),
             teacher_action=np.zeros((n, 6), np.float32),
             teacher_psi=rng.standard_normal((n, 10)).astype(np.float32),
             context=np.zeros((n, 1)))
    store = EpisodeStore(1000)
    store.load(cache)
    assert store.episodes[0].state.shape == (n, 0)
    code = main(['--task', TASK, '--teacher', str(TEACHER), '--config', str(tiny),
                 '--out', str(tmp_path / 'run'), '--rounds', '1', '--updates', '1',
                 '--window', '8', '--head', 'teacher', '--data-cache', str(cache),
                 '--no-progress'])
    err = capsys.readouterr().err
    assert code == 2 and 'holds no states' in err and str(cache) in err


@pytest.mark.slow
def test_a_run_stopped_mid_round_resumes_to_the_same_student(
        tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C in round 2's collection, then --resume: the student of a run that never stopped."""
    from zeus_ros.offline.training import distill as library

    def run(out: Path, *extra: str) -> int:
        return main(['--task', TASK, '--teacher', str(TEACHER), '--config', str(tiny),
                     '--out', str(out), '--rounds', '3', '--first-steps', '45',
                     '--round-steps', '42', '--updates', '3', '--window', '8',
                     '--no-progress', *extra])

    assert run(tmp_path / 'whole') == 0
    real = library.collect_round
    calls = []

    def stopped_in_round_two(*args: object, **kwargs: object) -> object:
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(library, 'collect_round', stopped_in_round_two)
    out = tmp_path / 'stopped'
    with pytest.raises(KeyboardInterrupt):
        run(out)
    monkeypatch.setattr(library, 'collect_round', real)
    assert (out / 'resume.pt').is_file() and not (out / 'student.pt').exists()
    capsys.readouterr()
    assert run(out) == 2
    assert 'holds a stopped run' in capsys.readouterr().err
    assert run(out, '--updates', '4', '--resume') == 2
    assert 'updates (3, now 4)' in capsys.readouterr().err
    assert run(out, '--resume') == 0
    assert 'resumed after round 1' in capsys.readouterr().out
    assert not (out / 'resume.pt').exists() and not (out / 'rounds').exists()
    whole = torch.load(tmp_path / 'whole' / 'student.pt', weights_only=False)['state']['modules']
    resumed = torch.load(out / 'student.pt', weights_only=False)['state']['modules']
    assert whole.keys() == resumed.keys()
    for name, state in whole.items():
        for key, value in state.items():
            assert torch.equal(value, resumed[name][key]), (name, key)
    rounds = [row.split(',')[:2] for row in (out / 'rounds.csv').read_text().splitlines()[1:]]
    assert rounds == [['0', 'teacher'], ['1', 'student'], ['2', 'student']]
