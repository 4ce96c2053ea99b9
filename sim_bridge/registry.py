"""Task names -> task classes; the one way to build a task (the node, collect and eval use it)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
import importlib

from sim_bridge.core import ContextualTask

__all__ = ['TASK_NAMES', 'make_task']

_TASKS: dict[str, tuple[str, str]] = {
    'Cheetah-Run-v0': ('sim_bridge.cheetah', 'CheetahRunTask'),
    'Cheetah-Run-v1': ('sim_bridge.cheetah', 'CheetahVelocityTask'),
    'Walker-Walk-v0': ('sim_bridge.walker', 'WalkerFrictionTask'),
    'Walker-Walk-v1': ('sim_bridge.walker', 'WalkerFootTask'),
    'Finger-Spin-v0': ('sim_bridge.finger', 'FingerSpinTask'),
    'Sawyer-Peg-v0': ('sim_bridge.sawyer', 'SawyerPegTask'),
}
TASK_NAMES: tuple[str, ...] = tuple(_TASKS)


def task_class(name: str) -> Callable[..., ContextualTask]:
    """The class of a task, imported on demand (MuJoCo models load only when used)."""
    if name not in _TASKS:
        raise ValueError(f'unknown task {name!r}; valid tasks: {", ".join(TASK_NAMES)}')
    module, cls = _TASKS[name]
    try:
        return getattr(importlib.import_module(module), cls)
    except ImportError as error:
        raise ValueError(f'task {name!r} is not available here: {error}') from error


def make_task(name: str, *, seed: int | None = None,
              context: Mapping[str, float] | None = None) -> ContextualTask:
    """Build a task by its paper name, optionally with a starting context."""
    return task_class(name)(seed=seed, context=context)
