"""Keep a pixel student up with its retrained teacher, without distilling it again.

A `zeus distill --head teacher` student is a conv phi trained to read the teacher's state
features from frames, in front of the teacher's own psi and actor, frozen (distill.py). A
continual round (continual.py) freezes the teacher's phi and psi and trains only its actor,
since the gated actor (learning/gated_actor.py) a copy beside the deployed one. So the
retrained teacher differs from the one the student was distilled from only in its actor, and
that actor can be moved into the student as it is: the student's phi(o) already stands in for
the teacher's phi(s), its psi is the teacher's psi. Distilling again would cost 30-40 minutes
of rendering on a 2-core CPU per candidate; this costs one file write.

Refused (with what to do) where that reasoning does not hold: a student with its own head,
a teacher whose psi (or context normaliser) is not the student's, another task or action size.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from zeus_ros.learning.checkpoint import LoadedCheckpoint, load_checkpoint, save_deployment
from zeus_ros.learning.gated_actor import GatedActor

__all__ = ['RefreshError', 'refresh_student']

SHARED = ('psi', 'context_norm')
"""Networks the student shares with its teacher, frozen: they must be equal for the move."""


class RefreshError(ValueError):
    """The student cannot take this teacher's actor; the message says why and what to do."""


def refresh_student(student: str | Path, teacher: str | Path, out: str | Path,
                    *, task: str | None = None, teacher_sha256: str = '') -> Path:
    """Write `out`: the pixel `student` acting with `teacher`'s actor (gated or plain)."""
    pixel = load_checkpoint(student, load_optimizers=False, expect_task=task)
    state = load_checkpoint(teacher, load_optimizers=False, expect_task=task)
    _check(pixel, state, Path(student), Path(teacher))
    agent = pixel.agent
    actor = state.agent.modules['actor']
    if isinstance(actor, GatedActor):
        if isinstance(agent.modules['actor'], GatedActor):  # refreshed before: start again
            agent.modules['actor'] = agent.modules['actor'].base
            agent.config = agent.config.replace(actor_gate=0)
        gate = [getattr(actor, name).cpu().numpy() for name in ('centroids', 'scale', 'low',
                                                                'high')]
        agent.gate_actor(gate[0], float(gate[1]), float(gate[2]), float(gate[3]))
    agent.modules['actor'].load_state_dict(actor.state_dict())
    agent.modules['actor'].requires_grad_(False)
    extra: dict[str, Any] = dict(pixel.extra)
    extra['refresh'] = {'teacher': str(teacher), 'teacher_sha256': teacher_sha256,
                        'student': str(student)}
    return save_deployment(out, agent, step=pixel.step, extra=extra)


def _check(pixel: LoadedCheckpoint, state: LoadedCheckpoint, student: Path,
           teacher: Path) -> None:
    """Refuse a pair whose shared networks differ (the student would read another psi)."""
    head = ((pixel.extra.get('distill') or {}).get('settings') or {}).get('head')
    if pixel.config.obs_kind != 'pixels' or head != 'teacher':
        raise RefreshError(
            f'{student}: not a teacher-head pixel student (obs {pixel.config.obs_kind}, head '
            f"{head}); only `zeus distill --head teacher` students share their teacher's psi "
            'and actor: distil this one again from the new teacher')
    if state.config.obs_kind != 'state' or state.spec.task != pixel.spec.task or \
            state.spec.action_dim != pixel.spec.action_dim:
        raise RefreshError(f'{teacher}: a {state.config.obs_kind} checkpoint of '
                           f'{state.spec.task}; the student {student} needs a state teacher of '
                           f'{pixel.spec.task}')
    for name in SHARED:
        ours, theirs = pixel.agent.modules.get(name), state.agent.modules.get(name)
        if (ours is None) != (theirs is None) or (ours is not None and theirs is not None and
                                                  not _equal(ours, theirs)):
            raise RefreshError(
                f'{teacher}: its {name} is not the one {student} was distilled with (a round '
                'that trained the representation, or another teacher); distil the student '
                'again from it (zeus distill --head teacher)')


def _equal(ours: torch.nn.Module, theirs: torch.nn.Module) -> bool:
    a, b = ours.state_dict(), theirs.state_dict()
    return a.keys() == b.keys() and all(torch.equal(a[k].cpu(), b[k].cpu()) for k in a)
