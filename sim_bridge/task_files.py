"""Tasks declared in YAML files: a robot (its robot_bridge params) or a MuJoCo model.

One reader for every tool: `make_task('my_task.yaml')` and `--task-file` end up here. A file
holding a `robot_bridge: ros__parameters:` section declares a robot (sim_bridge/robot.py); a
file with a `model:` declares a simulated task (sim_bridge/mjcf_task.py).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import yaml

from sim_bridge.core import ContextualTask
from zeus_ros.yaml_text import safe_load_params

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


def read_yaml(path: Path, what: str = 'task file') -> Any:
    """The YAML content of `path`; ValueError in one line naming the file."""
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise ValueError(f'{what} {path} does not exist') from None
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f'{what} {path}: cannot read it as UTF-8 text ({error})') from None
    try:
        return safe_load_params(text)  # a robot's params file, as rcl reads it
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        where = f' line {mark.line + 1}' if mark is not None else ''
        raise ValueError(f'{what} {path}{where}: not valid YAML '
                         f'({getattr(error, "problem", None) or error})') from None


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
    raise ValueError(f'task file {path}: expected a robot_bridge: ros__parameters: section '
                     '(a robot) or a MuJoCo task (model:, observation:, context:)')
