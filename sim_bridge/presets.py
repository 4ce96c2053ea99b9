"""The paper's context value tables as named presets (params/contexts/<task>.yaml).

A task declared in a task file carries its presets in the file (`presets:`), same format.
"""

from __future__ import annotations

from functools import cache
import os
from pathlib import Path
from typing import Any

import yaml

__all__ = ['SPLITS', 'find_params_dir', 'load_preset']

SPLITS = ('train', 'interpolation', 'extrapolation')


def find_params_dir() -> Path:
    """The params/ directory: this checkout, else share/zeus_ros/params of an ament prefix."""
    candidates = [Path(__file__).resolve().parents[1] / 'params']
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            candidates.append(Path(prefix) / 'share' / 'zeus_ros' / 'params')
    for candidate in candidates:
        if (candidate / 'contexts').is_dir():
            return candidate
    raise FileNotFoundError(
        'no params/contexts directory found; looked in ' + ', '.join(map(str, candidates)))


@cache
def _preset_file(task: str) -> dict[str, Any]:
    from sim_bridge.registry import declared_task

    declared = declared_task(task)
    if declared is not None:  # a task file carries its own presets
        if not declared.presets:
            raise ValueError(f'{task}: its task file {declared.source} declares no presets; add '
                             'presets: {train: [...], interpolation: [...], extrapolation: [...]}')
        single = declared.parameters[0] if len(declared.parameters) == 1 else None
        return {'parameter': single, **declared.presets}
    path = find_params_dir() / 'contexts' / f'{task}.yaml'
    if not path.is_file():
        known = sorted(p.stem for p in path.parent.glob('*.yaml'))
        raise ValueError(f'no context presets for task {task!r}; presets exist for {known}')
    return yaml.safe_load(path.read_text())


def load_preset(task: str, split: str) -> list[dict[str, float]]:
    """Context values of one split, each as {parameter: value}."""
    data = _preset_file(task)
    if split not in SPLITS or split not in data:
        available = [s for s in SPLITS if s in data]
        raise ValueError(f'{task}: unknown preset split {split!r}; choose one of {available}')
    parameter = data.get('parameter')
    values = []
    for entry in data[split]:
        if isinstance(entry, dict):
            values.append({str(k): float(v) for k, v in entry.items()})
        else:
            values.append({str(parameter): float(entry)})
    return values
