"""The schema of a family file: reading it, its context parameters and its preset lists.

The parts of sim_bridge/families.py that the task-file reader needs too (a user's copy of a
built-in family file is read as a task file: `declared_copy`); below the registry, so neither
imports the other in a circle.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import cache
import math
from pathlib import Path
from typing import Any

import yaml

from sim_bridge.builtins import TASK_NAMES
from sim_bridge.core import ContextSpec
from sim_bridge.presets import SPLITS, find_params_dir
from zeus_ros.yaml_text import safe_load_params

__all__ = ['FILE_KEYS', 'builtin_family_file', 'builtin_specs', 'declared_copy', 'number',
           'parse_presets', 'parse_specs', 'read_yaml']

FILE_KEYS = {'task', 'builtin', 'varies', 'context', 'presets', 'training', 'checkpoint',
             'demo'}
"""The keys of a family file (built-in or a user's copy)."""


def builtin_family_file(task: str) -> Path:
    """`params/tasks/<task>.yaml` of this checkout or the installed share."""
    return find_params_dir() / 'tasks' / f'{task}.yaml'


@cache
def builtin_specs(task: str) -> tuple[ContextSpec, ...]:
    """The context parameters a built-in family's file declares (what its class accepts)."""
    path = builtin_family_file(task)
    data = read_yaml(path, what='task family file')
    return parse_specs(data.get('context') if isinstance(data, Mapping) else None,
                       f'task family file {path}')


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


def declared_copy(path: Path, data: Mapping[str, Any]
                  ) -> tuple[str, str, tuple[ContextSpec, ...], dict[str, Any]]:
    """A user's copy of a built-in family file: (its task name, the built-in, specs, presets).

    The copy runs the built-in's simulator (`builtin:`, default: its `task:` when that is a
    built-in name) with the file's own context ranges, presets, training defaults, checkpoint
    and demo; it may narrow the built-in's parameters' ranges, not add parameters or widen them
    (the simulator accepts no more). ValueError naming the file and the entry.
    """
    where = f'task file {path}'
    unknown = sorted(set(data) - FILE_KEYS)
    if unknown:
        raise ValueError(f'{where}: unknown key(s) {unknown}; a family file has '
                         f'{sorted(FILE_KEYS)}')
    name = data.get('task')
    if not isinstance(name, str) or not name:
        raise ValueError(f'{where}: task: name your family (e.g. My-Bias-v0)')
    builtin = data.get('builtin', name)
    if builtin not in TASK_NAMES:
        raise ValueError(f'{where}: {builtin!r} is not a built-in family; a copied family file '
                         f'runs one: set builtin: to one of {", ".join(TASK_NAMES)}, or declare '
                         'a MuJoCo task (model:, observation:, context:; docs/tasks.md)')
    specs = parse_specs(data.get('context'), where)
    simulator = {spec.name: spec for spec in builtin_specs(builtin)}
    for spec in specs:
        base = simulator.get(spec.name)
        if base is None:
            raise ValueError(f'{where}: context {spec.name}: {builtin} simulates '
                             f'{", ".join(simulator)} only')
        if spec.low < base.low or spec.high > base.high:
            raise ValueError(f'{where}: context {spec.name}: range [{spec.low}, {spec.high}] '
                             f'is wider than {builtin} accepts ([{base.low}, {base.high}])')
    missing = sorted(set(simulator) - {spec.name for spec in specs})
    if missing:
        raise ValueError(f'{where}: context: declare every parameter of {builtin}; missing '
                         f'{missing}')
    presets = parse_presets(data.get('presets') or {}, tuple(s.name for s in specs), where)
    return name, builtin, specs, presets


def number(value: Any, where: str) -> float:
    """A finite-or-infinite number from YAML (not a bool, not NaN); ValueError naming `where`."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
        raise ValueError(f'{where}: expected a number, got {value!r}')
    return float(value)


def parse_specs(context: Any, where: str) -> tuple[ContextSpec, ...]:
    """A family file's `context:` as ContextSpecs (unit, default within range, doc)."""
    if not isinstance(context, Mapping) or not context:
        raise ValueError(f'{where}: context: declare each parameter, e.g. motor_bias: '
                         '{unit: ..., default: 0.0, range: [-1, 1], doc: ...}')
    specs = []
    for name, entry in context.items():
        here = f'{where}: context {name}'
        if not isinstance(entry, Mapping) or set(entry) - {'unit', 'default', 'range', 'doc'}:
            raise ValueError(f'{here}: expected a mapping with unit, default, range, doc')
        bounds = entry.get('range')
        if not isinstance(bounds, list) or len(bounds) != 2:
            raise ValueError(f'{here}: range must be [low, high]')
        low, high = (number(b, f'{here}: range') for b in bounds)
        default = number(entry.get('default'), f'{here}: default')
        if not low <= default <= high:
            raise ValueError(f'{here}: default {default} outside range [{low}, {high}]')
        specs.append(ContextSpec(str(name), default, low, high, str(entry.get('doc', '')),
                                 unit=str(entry.get('unit', ''))))
    return tuple(specs)


def parse_presets(raw: Any, parameters: tuple[str, ...], where: str
                  ) -> dict[str, tuple[dict[str, float], ...]]:
    """Preset lists per split as {parameter: value} dicts (a bare number: the only parameter)."""
    if not isinstance(raw, Mapping) or set(raw) - set(SPLITS):
        raise ValueError(f'{where}: presets: splits are {", ".join(SPLITS)}; got '
                         f'{sorted(raw) if isinstance(raw, Mapping) else raw!r}')
    single = parameters[0] if len(parameters) == 1 else None
    presets: dict[str, tuple[dict[str, float], ...]] = {}
    for split in SPLITS:
        if split not in raw:
            continue
        values = []
        for entry in raw[split] or []:
            if isinstance(entry, Mapping):
                unknown = sorted(set(map(str, entry)) - set(parameters))
                if unknown:
                    raise ValueError(f'{where}: presets: {split}: unknown parameter(s) '
                                     f'{unknown}; this task has {list(parameters)}')
                values.append({str(k): number(v, f'{where}: presets: {split}')
                               for k, v in entry.items()})
            elif single is not None:
                values.append({single: number(entry, f'{where}: presets: {split}')})
            else:
                raise ValueError(f'{where}: presets: {split}: with several parameters each '
                                 f'value is a mapping, e.g. {{{parameters[0]}: ...}}')
        presets[split] = tuple(values)
    return presets
