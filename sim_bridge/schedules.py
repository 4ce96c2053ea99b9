"""Context schedules: which value each context parameter has at each step (unannounced).

A schedule is a pure function of (global step index, episode index) given its seed, so a run is
reproducible and the node, the collector and the evaluator agree on every step. Kinds:

- constant:     `context: {name: value}` or `value: v` (single-parameter tasks)
- switch:       `values:` list of numbers / {name: value} maps / a preset split name
                (train, interpolation, extrapolation); `every: N` steps or
                `every_episodes: N`; `order: cycle | sample` (seeded)
- drift:        `shape: ramp | sinusoid`, `low`, `high`, `period` (steps); ramp goes low->high
                then restarts, sinusoid starts at the middle
- random_walk:  `low`, `high`, `step_size` (std of a Gaussian step), `every` (steps per move,
                default 1), `start` (default: middle); reflected at the bounds
`parameter:` names the context parameter for drift/random_walk/number lists when the task has
more than one.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping, Sequence
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from sim_bridge.families import load_preset
from sim_bridge.presets import SPLITS

if TYPE_CHECKING:
    from sim_bridge.core import ContextualTask

__all__ = ['KINDS', 'Schedule', 'schedule_from_config']

KINDS: dict[str, tuple[str, ...]] = {
    'constant': ('context', 'value', 'parameter'),
    'switch': ('values', 'every', 'every_episodes', 'order', 'parameter'),
    'drift': ('shape', 'low', 'high', 'period', 'parameter'),
    'random_walk': ('low', 'high', 'step_size', 'every', 'start', 'parameter'),
}


class Schedule(abc.ABC):
    """Maps (step, episode) to a full context; subclasses define `_value`."""

    def __init__(self, defaults: Mapping[str, float]) -> None:
        self.defaults = dict(defaults)

    def value_at(self, step: int, episode: int) -> dict[str, float]:
        """The context (every parameter) in force for observation `step` of `episode`."""
        return {**self.defaults, **self._value(step, episode)}

    @abc.abstractmethod
    def _value(self, step: int, episode: int) -> dict[str, float]:
        """The scheduled parameters only."""


class Constant(Schedule):
    """One context for the whole run."""

    def __init__(self, defaults: Mapping[str, float], context: Mapping[str, float]) -> None:
        super().__init__(defaults)
        self.context = dict(context)

    def _value(self, step: int, episode: int) -> dict[str, float]:
        return self.context


class Switch(Schedule):
    """Steps through a value list every N steps or every N episodes, cyclic or sampled."""

    def __init__(self, defaults: Mapping[str, float], values: list[dict[str, float]],
                 every: int | None, every_episodes: int | None, order: str, seed: int) -> None:
        super().__init__(defaults)
        self.values = values
        self.every = every
        self.every_episodes = every_episodes
        self.order = order
        self._rng = np.random.default_rng(seed)
        self._sampled: list[int] = []

    def _index(self, period: int) -> int:
        if self.order == 'cycle':
            return period % len(self.values)
        while len(self._sampled) <= period:  # extend the seeded sequence, never reorder it
            self._sampled.extend(self._rng.integers(len(self.values), size=256).tolist())
        return self._sampled[period]

    def _value(self, step: int, episode: int) -> dict[str, float]:
        period = step // self.every if self.every else episode // (self.every_episodes or 1)
        return self.values[self._index(period)]


class Drift(Schedule):
    """Smooth change inside [low, high]: a repeating ramp or a sinusoid."""

    def __init__(self, defaults: Mapping[str, float], parameter: str, shape: str, low: float,
                 high: float, period: int) -> None:
        super().__init__(defaults)
        self.parameter, self.shape = parameter, shape
        self.low, self.high, self.period = low, high, period

    def _value(self, step: int, episode: int) -> dict[str, float]:
        phase = (step % self.period) / self.period
        if self.shape == 'ramp':
            fraction = phase
        else:
            fraction = 0.5 + 0.5 * math.sin(2 * math.pi * phase)
        return {self.parameter: self.low + (self.high - self.low) * fraction}


class RandomWalk(Schedule):
    """Bounded Gaussian random walk, reflected at the bounds, extended lazily with its seed."""

    def __init__(self, defaults: Mapping[str, float], parameter: str, low: float, high: float,
                 step_size: float, every: int, start: float, seed: int) -> None:
        super().__init__(defaults)
        self.parameter, self.low, self.high = parameter, low, high
        self.step_size, self.every = step_size, every
        self._rng = np.random.default_rng(seed)
        self._walk = [start]

    def _reflect(self, value: float) -> float:
        width = self.high - self.low
        folded = (value - self.low) % (2 * width)
        return self.low + (folded if folded <= width else 2 * width - folded)

    def _value(self, step: int, episode: int) -> dict[str, float]:
        index = step // self.every
        while len(self._walk) <= index:
            moves = self._rng.normal(0.0, self.step_size, size=256)
            for move in moves:
                self._walk.append(self._reflect(self._walk[-1] + float(move)))
        return {self.parameter: self._walk[index]}


def _fail(message: str) -> ValueError:
    return ValueError(f'schedule: {message}')


def _number(config: Mapping[str, Any], key: str, default: float | None = None,
            positive: bool = False) -> float:
    value = config.get(key, default)
    if value is None:
        raise _fail(f'key {key!r} is required')
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _fail(f'{key} must be a finite number, got {value!r}')
    if positive and value <= 0:
        raise _fail(f'{key} must be > 0, got {value}')
    return float(value)


def _parameter(config: Mapping[str, Any], names: Sequence[str]) -> str:
    parameter = config.get('parameter')
    if parameter is None:
        if len(names) != 1:
            raise _fail(f'this task has several context parameters {list(names)}: say which '
                        "one with 'parameter'")
        return names[0]
    if parameter not in names:
        raise _fail(f'parameter {parameter!r} is not a context of this task; '
                    f'allowed: {list(names)}')
    return str(parameter)


def _values(config: Mapping[str, Any], task: ContextualTask) -> list[dict[str, float]]:
    raw = config.get('values')
    if raw is None:
        raise _fail("kind 'switch' needs 'values': a list or a preset split "
                    f'({", ".join(SPLITS)})')
    if isinstance(raw, str):
        return load_preset(task.name, raw)
    if not isinstance(raw, (list, tuple)) or not raw:
        raise _fail(f'values must be a non-empty list or a preset split name, got {raw!r}')
    out = []
    for entry in raw:
        if isinstance(entry, Mapping):
            out.append({str(k): float(v) for k, v in entry.items()})
        else:
            out.append({_parameter(config, task.context_names): float(entry)})
    return out


def schedule_from_config(config: Mapping[str, Any] | None, task: ContextualTask,
                         seed: int = 0) -> Schedule:
    """Build a schedule from a plain dict (YAML or ROS parameters); ValueError names the key.

    Every scheduled value is checked against the task's accepted ranges up front, so a bad
    value fails at start-up instead of in the middle of a run.
    """
    config = dict(config or {'kind': 'constant'})
    kind = config.pop('kind', 'constant')
    if kind not in KINDS:
        raise _fail(f'kind {kind!r} is not known; allowed: {", ".join(KINDS)}')
    unknown = sorted(set(config) - set(KINDS[kind]))
    if unknown:
        raise _fail(f'unknown key(s) {unknown} for kind {kind!r}; allowed: {list(KINDS[kind])}')
    names = task.context_names
    defaults = task.context
    specs = {spec.name: spec for spec in task.context_specs}
    if kind == 'constant':
        if 'context' in config:
            context = {str(k): float(v) for k, v in dict(config['context']).items()}
        elif 'value' in config:
            context = {_parameter(config, names): _number(config, 'value')}
        else:
            context = {}
        schedule: Schedule = Constant(defaults, context)
        probes: list[dict[str, float]] = [context]
    elif kind == 'switch':
        values = _values(config, task)
        every, episodes = config.get('every'), config.get('every_episodes')
        if (every is None) == (episodes is None):
            raise _fail("kind 'switch' needs exactly one of 'every' (steps) or "
                        "'every_episodes'")
        for key, value in (('every', every), ('every_episodes', episodes)):
            if value is not None and (not isinstance(value, int) or isinstance(value, bool)
                                      or value < 1):
                raise _fail(f'{key} must be an integer >= 1, got {value!r}')
        order = config.get('order', 'cycle')
        if order not in ('cycle', 'sample'):
            raise _fail(f"order {order!r} is not known; allowed: 'cycle', 'sample'")
        schedule = Switch(defaults, values, every, episodes, order, seed)
        probes = values
    else:
        parameter = _parameter(config, names)
        low, high = _number(config, 'low'), _number(config, 'high')
        if not low < high:
            raise _fail(f'low ({low}) must be below high ({high})')
        if kind == 'drift':
            shape = config.get('shape', 'sinusoid')
            if shape not in ('ramp', 'sinusoid'):
                raise _fail(f"shape {shape!r} is not known; allowed: 'ramp', 'sinusoid'")
            period = int(_number(config, 'period', positive=True))
            schedule = Drift(defaults, parameter, shape, low, high, period)
        else:
            every = int(_number(config, 'every', 1, positive=True))
            start = _number(config, 'start', (low + high) / 2)
            if not low <= start <= high:
                raise _fail(f'start ({start}) must lie in [{low}, {high}]')
            schedule = RandomWalk(defaults, parameter, low, high,
                                  _number(config, 'step_size', positive=True), every, start,
                                  seed)
        probes = [{parameter: low}, {parameter: high}]
    for probe in probes:
        for name, value in probe.items():
            spec = specs.get(name)
            if spec is None:
                raise _fail(f'{name!r} is not a context of {task.name}; allowed: {list(names)}')
            if not spec.low <= value <= spec.high:
                raise _fail(f'{name}={value} is outside the range {task.name} accepts '
                            f'[{spec.low}, {spec.high}]')
    return schedule
