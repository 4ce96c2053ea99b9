"""Tasks declared in YAML files: a robot (its robot_bridge params) or a MuJoCo model.

One reader for every tool: `make_task('my_task.yaml')` and `--task-file` end up here. A file
holding a `robot_bridge: ros__parameters:` section declares a robot (sim_bridge/robot.py).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from sim_bridge.core import ContextualTask

__all__ = ['DeclaredTask', 'load_task_file', 'read_yaml']


@dataclass(frozen=True)
class DeclaredTask:
    """A task file read and validated: its task name and how to build the task."""

    name: str
    factory: Callable[..., ContextualTask]
    source: Path
    simulated: bool = True
    """False for a robot: only robot_bridge steps it."""


def read_yaml(path: Path, what: str = 'task file') -> Any:
    """The YAML content of `path`; ValueError in one line naming the file."""
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise ValueError(f'{what} {path} does not exist') from None
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f'{what} {path}: cannot read it as UTF-8 text ({error})') from None
    try:
        return yaml.safe_load(text)
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

    def factory(seed: int | None = None, context: Mapping[str, float] | None = None
                ) -> ContextualTask:
        task = RobotTask(spec, path)
        if context:
            task.set_context(context)
        return task

    return DeclaredTask(spec.task, factory, path, simulated=False)


def load_task_file(path: Path) -> DeclaredTask:
    """Read and validate a task file; ValueError naming the file and what is wrong."""
    from sim_bridge.robot import robot_section

    data = read_yaml(path)
    robot = robot_section(data)
    if robot is not None:
        return _robot(path, robot)
    raise ValueError(f'task file {path}: expected a robot_bridge: ros__parameters: section '
                     '(a robot) or a MuJoCo task (model:, observation:, context:)')
