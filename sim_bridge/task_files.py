"""Tasks declared in YAML files: a robot (its robot_bridge params) or a MuJoCo model.

One reader for every tool: `make_task('my_task.yaml')` and `--task-file` end up here. A file
holding a `robot_bridge: ros__parameters:` section declares a robot (sim_bridge/robot.py); a
file with a `model:` declares a simulated task (sim_bridge/mjcf_task.py); a copy of a built-in
family file (`task:`, `context:`, no `model:`) is the user's own family on that family's
simulator (sim_bridge/families.py: `declared_copy`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

from sim_bridge.builtins import builtin_class
from sim_bridge.core import ContextualTask
from sim_bridge.family_schema import declared_copy, read_yaml

__all__ = ['DeclaredTask', 'TaskFactory', 'load_task_file', 'read_yaml']


@dataclass(frozen=True)
class TaskFactory:
    """Builds the declared task, like a task class; carries what the tools read of a class."""

    build: Callable[..., ContextualTask]
    name: str
    episode_length: int
    specs: tuple[Any, ...] = ()
    """The context parameters (ContextSpec), as a task class's `specs`."""

    def __call__(self, seed: int | None = None, context: Mapping[str, float] | None = None,
                 **kwargs: Any) -> ContextualTask:
        """A new task instance."""
        return self.build(seed=seed, context=context, **kwargs)


@dataclass(frozen=True)
class DeclaredTask:
    """A task file read and validated: its task name and how to build the task."""

    name: str
    factory: TaskFactory
    source: Path
    simulated: bool = True
    """False for a robot: only robot_bridge steps it."""
    presets: Mapping[str, list[Any]] = field(default_factory=dict)
    """Context values per split (train / interpolation / extrapolation), as a family file's."""
    parameters: tuple[str, ...] = ()


def _robot(path: Path, params: Mapping[str, Any]) -> DeclaredTask:
    from sim_bridge.robot import RobotSpec, RobotTask

    try:
        spec = RobotSpec.from_params(params)
    except ValueError as error:
        raise ValueError(f'task file {path}: {error}') from None

    def build(seed: int | None = None, context: Mapping[str, float] | None = None
              ) -> ContextualTask:
        task = RobotTask(spec, path)
        if context:
            task.set_context(context)
        return task

    task = RobotTask(spec, path)
    factory = TaskFactory(build, spec.task, spec.episode_length, task.context_specs)
    return DeclaredTask(spec.task, factory, path, simulated=False)


def _mjcf(path: Path, data: Mapping[str, Any]) -> DeclaredTask:
    from sim_bridge.mjcf_task import MjcfTask, parse_mjcf_task

    spec = parse_mjcf_task(path, data)
    MjcfTask(spec).close()  # builds once: every path, the reward and the model are checked now
    factory = TaskFactory(partial(MjcfTask, spec), spec.name, spec.episode_length,
                          tuple(p.spec for p in spec.context))
    return DeclaredTask(spec.name, factory, path, presets=spec.presets,
                        parameters=tuple(p.spec.name for p in spec.context))


def _family_copy(path: Path, data: Mapping[str, Any]) -> DeclaredTask:
    """A copied family file: the built-in's class under the file's name and context specs."""
    name, builtin, specs, presets = declared_copy(path, data)
    base: Any = builtin_class(builtin)
    cls = type(base.__name__, (base,), {
        'name': name, 'specs': specs, '__module__': base.__module__,
        '__doc__': f'{name} ({path}): {builtin} simulates it'})
    factory = TaskFactory(cls, name, int(base.episode_length), specs)
    return DeclaredTask(name, factory, path, presets=presets,
                        parameters=tuple(spec.name for spec in specs))


_READ: dict[Path, tuple[float, DeclaredTask]] = {}
"""Task files read so far, with their modification time (a file is validated once)."""


def load_task_file(path: Path) -> DeclaredTask:
    """Read and validate a task file (once per version); ValueError naming what is wrong."""
    path = Path(path).absolute()
    try:
        mtime = path.stat().st_mtime
    except OSError:
        mtime = -1.0
    cached = _READ.get(path)
    if cached is not None and cached[0] == mtime:
        return cached[1]
    declared = _load(path)
    _READ[path] = (mtime, declared)
    return declared


def _load(path: Path) -> DeclaredTask:
    from sim_bridge.robot import robot_section

    data = read_yaml(path)
    robot = robot_section(data)
    if robot is not None:
        return _robot(path, robot)
    if isinstance(data, Mapping) and 'model' in data:
        return _mjcf(path, data)
    if isinstance(data, Mapping) and 'task' in data and 'context' in data:
        return _family_copy(path, data)
    raise ValueError(f'task file {path}: expected a robot_bridge: ros__parameters: section '
                     '(a robot), a MuJoCo task (model:, observation:, context:) or a copy of a '
                     'family file (task:, context:, e.g. params/tasks/Cheetah-Bias-v0.yaml)')
