"""Continual rounds for a deployed pixel student: train its state teacher, deploy the student.

A `zeus distill --head teacher` student acts with its state teacher's psi and actor behind a
conv phi (student_refresh.py). A round (continual.py) trains only the actor, so a pixel
deployment retrains the STATE teacher on the recording's state vectors (sim_bridge publishes
them beside the frames, the recorder records both), gates the state candidate against the
deployed teacher exactly as a state deployment would, and on a swap moves the candidate's
actor into the student (`refresh_student`): the nodes keep running pixels. Training the conv
student on frames instead would cost 30-40 minutes of rendering per candidate on 2 cores.

The teacher of a student is the one its record names: `extra['refresh']['teacher']` for a
student refreshed before (the actor it carries is that teacher's), else
`extra['distill']['teacher']`, checked against the recorded sha256; `teacher_path` says
where it looks.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from zeus_ros.system.continual_settings import TEACHER_SUFFIX

__all__ = ['STUDENT_FILE', 'StudentError', 'refresh_on_swap', 'state_teacher',
           'teacher_path']

STUDENT_FILE = 'student.pt'
"""The refreshed student, beside the round's candidate (OUT/round_NNN/student.pt)."""


class StudentError(ValueError):
    """A pixel checkpoint the trainer cannot run rounds for (one line: why, what to do)."""


def state_teacher(checkpoint: Path | str, teacher: Path | str | None = None) -> Path | None:
    """The state teacher a round trains for deployed `checkpoint`; None for a state one.

    `teacher`: the teacher already known (the trainer's last swap), used when it is a file.
    Raises StudentError for a pixel checkpoint that is not a teacher-head student, or whose
    teacher is not found.
    """
    from zeus_ros.learning.checkpoint import load_checkpoint

    loaded = load_checkpoint(checkpoint, load_optimizers=False)
    if loaded.config.obs_kind != 'pixels':
        return None
    distill = loaded.extra.get('distill') or {}
    head = (distill.get('settings') or {}).get('head')
    if head != 'teacher' or not distill.get('teacher'):
        raise StudentError(
            f'continual: {checkpoint} is a pixel checkpoint but not a teacher-head student '
            f'(head {head}): a round trains the state teacher whose psi and actor the student '
            'shares; deploy a `zeus distill --head teacher` student, or a state checkpoint')
    if teacher is not None and Path(teacher).is_file():
        return Path(teacher).resolve()
    return teacher_path(Path(checkpoint), loaded.extra)


def teacher_path(student: Path, extra: dict[str, Any]) -> Path:
    """Where the teacher `extra` names is, the first place whose file has the recorded sha256.

    As named (absolute, else beside the student, in the package share, in the working
    directory), the copy beside a deployed student (TEACHER_SUFFIX), or the named file's name
    beside the student (the zoo keeps both in one folder). StudentError lists where it looked.
    """
    from zeus_ros.offline.evaluation.records import checkpoint_sha256
    from zeus_ros.system.launch_defaults import share_dir

    record = extra.get('refresh') or extra['distill']
    named = Path(str(record['teacher'])).expanduser()
    sha256 = str(record.get('teacher_sha256') or '')
    bases = [student.parent, share_dir(), Path.cwd()]
    places = [named] if named.is_absolute() else [base / named for base in bases]
    places += [student.with_name(student.stem + TEACHER_SUFFIX), student.parent / named.name]
    places = list(dict.fromkeys(Path(p).resolve() for p in places))
    for place in places:
        if place.is_file() and (not sha256 or checkpoint_sha256(place) == sha256):
            return place
    raise StudentError(
        f'continual: the state teacher of the pixel student {student} ({named}'
        f'{f", sha256 {sha256[:12]}" if sha256 else ""}) is not found; looked in '
        + ', '.join(str(p) for p in places)
        + ': put it there, or deploy a state checkpoint')


def refresh_on_swap(student: Path, task: str, forced: bool
                    ) -> Callable[[Any, Any], dict[str, Any]]:
    """The round's decision hook (continual_round's `on_decision`) in student mode.

    When the candidate is deployed (or `forced` past the gate), writes the refreshed student
    beside it (STUDENT_FILE); returns the history fields naming the deployed student and,
    then, the refreshed one (path and sha256 each).
    """
    from zeus_ros.offline.evaluation.records import checkpoint_sha256
    from zeus_ros.offline.training.student_refresh import refresh_student

    def decided(candidate: Any, result: Any) -> dict[str, Any]:
        fields: dict[str, Any] = {'student': str(student),
                                  'student_sha256': checkpoint_sha256(student)}
        if result.deploy or forced:
            path = refresh_student(student, candidate.path,
                                   Path(candidate.path).with_name(STUDENT_FILE), task=task,
                                   teacher_sha256=candidate.sha256)
            fields.update(refreshed_student=str(path),
                          refreshed_sha256=checkpoint_sha256(path))
        return fields
    return decided
