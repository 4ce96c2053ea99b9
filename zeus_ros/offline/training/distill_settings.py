"""What a distillation run does, without torch: the command line builds its flags from this.

`zeus distill --help` lists these settings before torch is imported (issue 52); the
distillation itself is offline/training/distill.py, which re-exports them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from zeus_ros.learning.errors import ConfigError

__all__ = ['DEFAULT_CONFIG', 'HEADS', 'TEACHER_HEAD_WITHOUT_PSI', 'DistillSettings']

DEFAULT_CONFIG = Path(__file__).resolve().parents[3] / 'params' / 'train' / 'pixels_student.yaml'


@dataclass(frozen=True)
class DistillSettings:
    """What the regression and the DAgger rounds do (the networks are the ZeusConfig's)."""

    rounds: int = 3
    """DAgger rounds: round 0 the teacher acts, rounds 1.. the student acts."""
    first_steps: int = 4000
    """Rendered steps of round 0."""
    round_steps: int = 1000
    """Rendered steps of every later round."""
    updates: int = 2000
    """Regression updates after each round (on everything stored)."""
    window: int = 20
    """Consecutive observations per sampled window (batch_size // window windows)."""
    psi_weight: float = 1.0
    """Weight of the psi regression (in units of the teacher psi's variance)."""
    noise: float = 0.1
    """Exploration noise of whoever acts, a fraction of half the action range."""
    shift: int = 4
    """Random-shift padding in pixels (0: no augmentation)."""
    max_steps: int = 20000
    """Stored observations at most (about 21 kB each)."""
    no_context: bool = False
    """A student without psi (the pixel `no_context` reference)."""
    head: str = 'own'
    """'own': the student's psi and actor are learnt; 'teacher': the teacher's, frozen."""
    feature_weight: float = 1.0
    """Weight of the phi(o) -> phi_T(s) regression (teacher head only)."""
    tune_head: float = 0.0
    """Teacher head: learning-rate factor of the copied psi and actor (0: frozen)."""

    def __post_init__(self) -> None:
        if self.head not in HEADS:
            raise ConfigError(f"head must be one of {', '.join(HEADS)}, not {self.head!r}")
        if self.head == 'teacher' and self.no_context:
            raise ConfigError(TEACHER_HEAD_WITHOUT_PSI)
        if self.tune_head and self.head != 'teacher':
            raise ConfigError('tune_head tunes the teacher head: give head teacher')


HEADS = ('own', 'teacher')
"""Who owns psi and the actor of the student (DistillSettings.head)."""
TEACHER_HEAD_WITHOUT_PSI = 'the teacher head acts on psi: it cannot be a no_context student'
