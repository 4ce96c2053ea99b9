"""A pixel student keeps up with its retrained teacher: the teacher's new actor, moved in.

Real zoo files: Cheetah-Bias-v0's teacher-head pixel student and its state teacher; the
"retrained" teacher is the zoo teacher gated the way a continual round gates it, with a
changed adapted copy (learning/gated_actor.py).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from zeus_ros.cli.distill import main
from zeus_ros.learning.checkpoint import load_checkpoint, save_deployment
from zeus_ros.learning.gated_actor import GatedActor
from zeus_ros.offline.training.student_refresh import RefreshError, refresh_student

REPO = Path(__file__).resolve().parents[1]
ZOO = REPO / 'checkpoints' / 'cheetah_bias_v0'
STUDENT, TEACHER = ZOO / 'pixels_student.pt', ZOO / 'zeus.pt'
TASK = 'Cheetah-Bias-v0'


def _candidate(path: Path, *, touch_psi: bool = False) -> Path:
    """The zoo teacher as a continual round leaves it: gated, its adapted copy trained."""
    loaded = load_checkpoint(TEACHER, load_optimizers=False)
    agent = loaded.agent
    rng = np.random.default_rng(0)
    agent.gate_actor(rng.standard_normal((4, agent.context_dim)), 2.0, 1.0, 1.5)
    with torch.no_grad():
        for p in agent.modules['actor'].adapted.parameters():
            p.add_(0.05 * torch.randn_like(p))
        if touch_psi:
            next(agent.modules['psi'].parameters()).add_(0.01)
    return save_deployment(path, agent, step=loaded.step, extra={})


def test_the_refreshed_student_acts_with_the_new_actor_and_keeps_its_eyes(
        tmp_path: Path) -> None:
    """Phi and psi stay the student's; the actor is the candidate's, gate included."""
    candidate = _candidate(tmp_path / 'candidate.pt')
    assert main(['--task', TASK, '--teacher', str(candidate), '--refresh', str(STUDENT),
                 '--out', str(tmp_path / 'out')]) == 0
    fresh = load_checkpoint(tmp_path / 'out' / 'student.pt', load_optimizers=False)
    old = load_checkpoint(STUDENT, load_optimizers=False)
    teacher = load_checkpoint(candidate, load_optimizers=False)
    actor = fresh.agent.modules['actor']
    assert isinstance(actor, GatedActor) and fresh.config.actor_gate == 4
    for name, want in (('encoder', old), ('psi', old), ('actor', teacher)):
        mine = fresh.agent.modules[name].state_dict()
        theirs = want.agent.modules[name].state_dict()
        assert all(torch.equal(mine[k], theirs[k]) for k in theirs), name
    assert fresh.extra['context_readout'] == old.extra['context_readout']
    assert fresh.extra['refresh']['teacher'] == str(candidate)
    # At a familiar context (a centroid) the student acts as before; at a novel one, anew.
    features = torch.zeros(1, fresh.agent.modules['encoder'].feature_dim)
    centroid = actor.centroids[:1]
    far = centroid + 100.0
    base = old.agent.modules['actor']
    assert torch.allclose(actor(torch.cat([features, centroid], -1)).mu,
                          base(torch.cat([features, centroid], -1)).mu)
    assert not torch.allclose(actor(torch.cat([features, far], -1)).mu,
                              base(torch.cat([features, far], -1)).mu)


def test_a_teacher_whose_psi_moved_is_refused_naming_what_to_do(tmp_path: Path) -> None:
    candidate = _candidate(tmp_path / 'candidate.pt', touch_psi=True)
    with pytest.raises(RefreshError, match=r'its psi is not the one .* distil the student again'):
        refresh_student(STUDENT, candidate, tmp_path / 'student.pt')
    assert not (tmp_path / 'student.pt').exists()


def test_a_state_checkpoint_is_not_a_student(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                             ) -> None:
    assert main(['--task', TASK, '--teacher', str(TEACHER), '--refresh', str(TEACHER),
                 '--out', str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'not a teacher-head pixel student' in err[0], err
