"""A task family is one declaration: `params/tasks/<Task>.yaml` (built-in) or a user task file.

Everything the tools know about a family is read here and nowhere else: its context parameters
(unit, default, range), the preset value lists per split, the training defaults that a config's
`auto` values resolve to, the zoo checkpoint it deploys and the schedule its demo runs.
A built-in family's file is named after its task, whose Python class simulates it. A user's
family is either a copy of such a file (`task:` their name, `builtin:` the family whose simulator
it runs, `declared_copy`) or a task file that declares the model itself (`model:`,
sim_bridge/mjcf_task.py); both may carry the same `training:`, `checkpoint:` and `demo:` sections.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from sim_bridge.core import ContextSpec
from sim_bridge.family_schema import (
    FILE_KEYS,
    builtin_family_file,
    declared_copy,
    number,
    parse_presets,
    parse_specs,
    read_yaml,
)
from sim_bridge.presets import SPLITS

__all__ = ['DEFAULT_TRAINING', 'DeclaredSpecs', 'TaskFamily', 'builtin_family_file',
           'declared_copy', 'family', 'load_preset', 'parse_presets']

DEFAULT_TRAINING: Mapping[str, float] = {'alpha_psi': 1.0, 'adam_beta1': 0.9}
"""Training defaults of a family that declares none: the paper's most common values."""

_TRAINING_KEYS = {'alpha_psi', 'adam_beta1'}
_DEMO_KEYS = {'values', 'every'}


@dataclass(frozen=True)
class TaskFamily:
    """One family's declaration, validated."""

    name: str
    source: Path
    specs: tuple[ContextSpec, ...]
    """Context parameters with unit, default and the range the task accepts."""
    presets: Mapping[str, tuple[dict[str, float], ...]]
    """Context values per split (SPLITS), each as {parameter: value}."""
    training: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_TRAINING))
    """What `alpha_psi: auto` and `adam_beta1: auto` resolve to for this family."""
    declared_training: frozenset[str] = frozenset()
    """The keys of `training` the file declares; the rest are DEFAULT_TRAINING, a guess."""
    checkpoint: str | None = None
    """The zoo checkpoint it deploys, relative to checkpoints/ (None: not in the zoo)."""
    varies: str = ''
    """What changes, in a few words (the zoo index and --help print it)."""
    demo_values: tuple[Any, ...] = ('train', 'extrapolation')
    """What the demo's schedule alternates between: split names or values."""
    demo_every: int | None = None
    """Steps between the demo's switches (None: half an episode for short episodes)."""

    def preset(self, split: str) -> list[dict[str, float]]:
        """Context values of one split; ValueError naming the splits this family has."""
        if split not in SPLITS or split not in self.presets:
            available = [s for s in SPLITS if s in self.presets]
            raise ValueError(f'{self.name}: unknown preset split {split!r}; choose one of '
                             f'{available} ({self.source})')
        return [dict(value) for value in self.presets[split]]

    def demo_schedule(self) -> tuple[int, list[float] | str]:
        """(steps between switches, values) of the family's demo and `zeus launch --task`.

        Values alternate between the demo's splits (or are its own list); a family with several
        context parameters cycles through its first split by name (sim_bridge's preset form).
        Short episodes switch mid-episode (half an episode); long ones every 150 steps.
        """
        from sim_bridge.registry import task_class

        episode = int(getattr(task_class(self.name), 'episode_length', 0) or 0)
        every = self.demo_every or (episode // 2 if 0 < episode <= 100 else 150)
        lists = [[float(next(iter(v.values()))) for v in self.preset(item)]
                 if isinstance(item, str) else [float(item)] for item in self.demo_values]
        if len(self.specs) > 1:
            first = next((i for i in self.demo_values if isinstance(i, str)), 'train')
            return every, first
        if all(not isinstance(item, str) for item in self.demo_values):
            return every, [float(item) for item in self.demo_values]
        values = []
        for index in range(max(len(values_) for values_ in lists)):
            values += [values_[index % len(values_)] for values_ in lists]
        return every, values

    def unit(self, parameter: str) -> str:
        """The unit of one context parameter ('' when dimensionless or undeclared)."""
        return next((s.unit for s in self.specs if s.name == parameter), '')


class DeclaredSpecs:
    """A built-in task class's `specs`, read from its family file on first use.

    `specs = DeclaredSpecs()` in the class body: the file is the one place that states them.
    """

    def __get__(self, instance: object, owner: type) -> tuple[ContextSpec, ...]:
        """The owner class's context parameters (by its `name`)."""
        return family(owner.name).specs  # type: ignore[attr-defined]


def family(task: str) -> TaskFamily:
    """The family of a task name or task file; ValueError naming the file and the entry."""
    from sim_bridge.registry import declared_task

    declared = declared_task(task)
    if declared is not None:  # read each time: task_files re-reads a file that changed
        data = read_yaml(declared.source)
        return _family(declared.name, declared.source, data, declared.factory.specs)
    return _builtin_family(task)


def load_preset(task: str, split: str) -> list[dict[str, float]]:
    """Context values of one split, each as {parameter: value} (from the task's family)."""
    return family(task).preset(split)


@cache
def _builtin_family(task: str) -> TaskFamily:
    from sim_bridge.builtins import TASK_NAMES

    if task not in TASK_NAMES:
        raise ValueError(f'unknown task {task!r}: choose one of {", ".join(TASK_NAMES)}, '
                         'or pass a task file (docs/tasks.md)')
    path = builtin_family_file(task)
    data = read_yaml(path, what='task family file')
    if not isinstance(data, Mapping):
        raise ValueError(f'task family file {path}: expected a mapping of keys')
    unknown = sorted(set(data) - FILE_KEYS)
    if unknown:
        raise ValueError(f'task family file {path}: unknown key(s) {unknown}; known: '
                         f'{sorted(FILE_KEYS)}')
    if data.get('task') != task:
        raise ValueError(f'task family file {path}: task is {data.get("task")!r}, '
                         f'expected {task!r} (the file name)')
    specs = parse_specs(data.get('context'), f'task family file {path}')
    return _family(task, path, data, specs)


def _family(name: str, path: Path, data: Mapping[str, Any],
            specs: tuple[ContextSpec, ...]) -> TaskFamily:
    where = f'{path}'
    names = tuple(s.name for s in specs)
    presets = parse_presets(data.get('presets') or {}, names, where)
    for split, values in presets.items():
        for value in values:
            for spec in specs:
                v = value.get(spec.name)
                if v is not None and not spec.low <= v <= spec.high:
                    raise ValueError(f'{where}: presets: {split}: {spec.name} {v} outside '
                                     f'its range [{spec.low}, {spec.high}]')
    training = dict(DEFAULT_TRAINING)
    raw_training = data.get('training') or {}
    if not isinstance(raw_training, Mapping) or set(raw_training) - _TRAINING_KEYS:
        raise ValueError(f'{where}: training: expected a mapping with keys '
                         f'{sorted(_TRAINING_KEYS)}, got {raw_training!r}')
    for key, value in raw_training.items():
        training[key] = number(value, f'{where}: training: {key}')
    if not 0.0 <= training['adam_beta1'] < 1.0 or training['alpha_psi'] < 0.0:
        raise ValueError(f'{where}: training: alpha_psi must be >= 0 and adam_beta1 in [0, 1)')
    demo = data.get('demo') or {}
    if not isinstance(demo, Mapping) or set(demo) - _DEMO_KEYS:
        raise ValueError(f'{where}: demo: expected a mapping with keys {sorted(_DEMO_KEYS)}')
    values = tuple(demo.get('values', ('train', 'extrapolation')))
    for item in values:
        if isinstance(item, str) and item not in presets:
            raise ValueError(f'{where}: demo: values: {item!r} is not a preset split here '
                             f'({", ".join(presets) or "none declared"})')
    every = demo.get('every')
    if every is not None and (not isinstance(every, int) or every < 1):
        raise ValueError(f'{where}: demo: every must be a positive number of steps')
    checkpoint = data.get('checkpoint')
    if checkpoint is not None and not isinstance(checkpoint, str):
        raise ValueError(f'{where}: checkpoint must be a path under checkpoints/')
    return TaskFamily(name=name, source=path, specs=specs, presets=presets, training=training,
                      declared_training=frozenset(raw_training), checkpoint=checkpoint,
                      varies=str(data.get('varies', '')), demo_values=values, demo_every=every)
