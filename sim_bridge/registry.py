"""Task names -> task classes; the one way to build a task (the node, collect and eval use it).

Besides the built-in families, a task can be declared in a YAML file (sim_bridge/task_files.py):
`make_task('path/to/task.yaml')` builds it, and `register_task_file(path)` makes its name known
(so bags that name it can be trained on).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from sim_bridge.builtins import TASK_NAMES, builtin_class

if TYPE_CHECKING:  # not at run time: sim_bridge.core imports numpy, a --help does not need it
    from sim_bridge.core import ContextualTask
    from sim_bridge.task_files import DeclaredTask

__all__ = ['TASK_NAMES', 'builtin_class', 'declared_task', 'is_simulated', 'is_task_file',
           'make_task', 'register_task_file', 'task_class']

_FILE_TASKS: dict[str, Path] = {}
"""Task name -> the YAML file that declares it (registered with register_task_file)."""


def is_task_file(name: str) -> bool:
    """True when `name` is a path to a YAML task file rather than a task name."""
    return name.endswith(('.yaml', '.yml'))


def register_task_file(path: str | Path) -> str:
    """Read a task file, remember it under its task name and return that name (ValueError)."""
    from sim_bridge.task_files import load_task_file

    declared = load_task_file(Path(path))
    _FILE_TASKS[declared.name] = Path(path).resolve()
    return declared.name


def declared_task(name: str) -> DeclaredTask | None:
    """The task file behind a registered task name or a path (registered then), else None."""
    if not (is_task_file(name) or name in _FILE_TASKS):
        return None
    from sim_bridge.task_files import load_task_file

    declared = load_task_file(_FILE_TASKS.get(name, Path(name)))
    _FILE_TASKS.setdefault(declared.name, declared.source)  # its presets, evaluation by name
    return declared


def is_simulated(name: str) -> bool:
    """False for a task that only a robot can step (declared by robot_bridge params)."""
    declared = declared_task(name)
    return declared.simulated if declared is not None else name in TASK_NAMES


def task_class(name: str) -> Callable[..., ContextualTask]:
    """The class of a task, imported on demand (MuJoCo models load only when used)."""
    declared = declared_task(name)
    if declared is not None:
        return declared.factory
    return builtin_class(name)


def make_task(name: str, *, seed: int | None = None,
              context: Mapping[str, float] | None = None) -> ContextualTask:
    """Build a task by its paper name or task file, optionally with a starting context."""
    return task_class(name)(seed=seed, context=context)
