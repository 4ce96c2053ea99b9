"""One module per training objective; the registry that names them is learning/methods.py."""

from zeus_ros.learning.objectives.base import (
    LossHost,
    Objective,
    PsiObjective,
    PsiStep,
    RepresentationLosses,
)

__all__ = ['LossHost', 'Objective', 'PsiObjective', 'PsiStep', 'RepresentationLosses']
