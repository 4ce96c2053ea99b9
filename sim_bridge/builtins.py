"""The built-in task families: their names and the classes that simulate them.

Imports no other sim_bridge module (a class is imported when first used), so the task-file
reader, the family schema and the registry can all name the built-ins without an import circle.
"""

from __future__ import annotations

from collections.abc import Callable
import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sim_bridge.core import ContextualTask

__all__ = ['TASK_NAMES', 'builtin_class']

_TASKS: dict[str, tuple[str, str]] = {
    'Cheetah-Run-v0': ('sim_bridge.cheetah', 'CheetahRunTask'),
    'Cheetah-Run-v1': ('sim_bridge.cheetah', 'CheetahVelocityTask'),
    'Cheetah-Motor-v0': ('sim_bridge.cheetah', 'CheetahMotorTask'),
    'Cheetah-Bias-v0': ('sim_bridge.cheetah', 'CheetahBiasTask'),
    'Walker-Walk-v0': ('sim_bridge.walker', 'WalkerFrictionTask'),
    'Walker-Walk-v1': ('sim_bridge.walker', 'WalkerFootTask'),
    'Finger-Spin-v0': ('sim_bridge.finger', 'FingerSpinTask'),
    'Sawyer-Peg-v0': ('sim_bridge.sawyer', 'SawyerPegTask'),
}
TASK_NAMES: tuple[str, ...] = tuple(_TASKS)

def builtin_class(name: str) -> Callable[..., ContextualTask]:
    """A built-in family's class, also while a copy of its file is registered under its name."""
    if name not in _TASKS:
        raise ValueError(f'unknown task {name!r}; valid tasks: {", ".join(TASK_NAMES)}, '
                         'or a task file (.yaml)')
    module, cls = _TASKS[name]
    try:
        return getattr(importlib.import_module(module), cls)
    except ImportError as error:
        raise ValueError(f'task {name!r} is not available here: {error}') from error
