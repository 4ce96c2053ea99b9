"""Attribute paths into a MuJoCo model or its state: `geom:floor.friction[0]`, `option.gravity[2]`.

Grammar: `KIND:NAME.ATTRIBUTE[INDEX,...]` or `option.ATTRIBUTE[INDEX]`, where KIND is an element
kind (body, geom, joint, site, actuator, sensor, ...), NAME an element name or `*` (every element
of the kind in id order; bodies: every body but the world), and the index optional. Context
parameters write such paths into an `MjSpec` (then the model is recompiled, so masses and
inertias follow geometry); observations read them from `MjData` (`joint:*.qvel`,
`body:torso.xpos[2]`, `sensor:accel.data`). Every error names the path, and for an unknown
element lists the model's elements of that kind.
"""

from __future__ import annotations

from dataclasses import dataclass
import re
from typing import Any

import mujoco
import numpy as np

__all__ = ['ModelPath', 'parse_path']

_PATTERN = re.compile(r'^(?:(?P<kind>[a-z]+):(?P<name>[^.\[\]]+)|(?P<option>option))'
                      r'\.(?P<attr>[a-z_0-9]+)(?:\[(?P<index>[0-9,\s]+)\])?$')
_PLURAL = {'body': 'bodies'}
_COUNTS = {'body': 'nbody', 'joint': 'njnt', 'geom': 'ngeom', 'site': 'nsite',
           'sensor': 'nsensor', 'actuator': 'nu', 'tendon': 'ntendon', 'camera': 'ncam'}


@dataclass(frozen=True)
class ModelPath:
    """One parsed path."""

    text: str
    kind: str
    """Element kind, or 'option'."""
    name: str
    """Element name, '*' for all, '' for option."""
    attr: str
    index: tuple[int, ...]

    def _spec_elements(self, spec: mujoco.MjSpec) -> list[Any]:
        if self.kind == 'option':
            return [spec.option]
        listing = getattr(spec, _PLURAL.get(self.kind, self.kind + 's'), None)
        if listing is None:
            raise ValueError(f'{self.text}: unknown element kind {self.kind!r}; use body, geom, '
                             'joint, site, actuator, sensor, tendon, ... or option')
        elements = [e for e in listing if not (self.kind == 'body' and e.name == 'world')]
        if self.name == '*':
            if not elements:
                raise ValueError(f'{self.text}: the model has no {self.kind}')
            return elements
        found = [e for e in elements if e.name == self.name]
        if not found:
            names = ', '.join(e.name or '(unnamed)' for e in elements) or 'none'
            raise ValueError(f"{self.text}: no {self.kind} named {self.name!r}; the model's "
                             f'{_PLURAL.get(self.kind, self.kind + "s")}: {names}')
        return found

    def _check_value(self, element: Any, value: Any) -> np.ndarray:
        """The attribute as a float array; ValueError when it is not numeric or too short."""
        if value is None or isinstance(value, str):
            raise ValueError(f'{self.text}: {self.attr} is not a number or number array')
        array = np.atleast_1d(np.asarray(value, dtype=np.float64))
        if self.index and max(self.index) >= array.size:
            raise ValueError(f'{self.text}: index {max(self.index)} out of range; {self.attr} '
                             f'has {array.size} value(s)')
        if not self.index and array.size != 1:
            raise ValueError(f'{self.text}: {self.attr} has {array.size} values; pick one, '
                             f'e.g. {self.attr}[0]')
        return array

    def spec_read(self, spec: mujoco.MjSpec) -> list[np.ndarray]:
        """The addressed values in the spec, one array per element (validates the path)."""
        out = []
        for element in self._spec_elements(spec):
            if not hasattr(element, self.attr):
                known = sorted(a for a in dir(element) if not a.startswith('_'))
                raise ValueError(f'{self.text}: a {self.kind} has no attribute {self.attr!r}; '
                                 f'it has: {", ".join(known)}')
            if self.kind == 'body' and self.attr == 'mass' and not element.explicitinertial:
                raise ValueError(f'{self.text}: body {element.name!r} takes its mass from its '
                                 'geoms (no <inertial>): use geom:NAME.mass, or give the body '
                                 'an <inertial> element')
            array = self._check_value(element, getattr(element, self.attr))
            out.append(array[list(self.index)] if self.index else array)
        return out

    def spec_write(self, spec: mujoco.MjSpec, values: list[np.ndarray]) -> None:
        """Write one value array per element (as `spec_read` returned them)."""
        for element, value in zip(self._spec_elements(spec), values, strict=True):
            current = getattr(element, self.attr)
            if self.index:
                array = np.array(current, dtype=np.float64)
                array[list(self.index)] = value
                setattr(element, self.attr, array)
            elif isinstance(current, (int, np.integer)) and not isinstance(current, bool):
                setattr(element, self.attr, round(float(value[0])))
            else:
                setattr(element, self.attr, float(value[0]))

    def data_names(self, model: mujoco.MjModel) -> list[str]:
        """The element names this path reads from MjData, in id order (validates kind/name)."""
        count = getattr(model, _COUNTS[self.kind], None) if self.kind in _COUNTS else None
        if count is None:
            raise ValueError(f'{self.text}: observations read body, joint, geom, site, sensor, '
                             f'actuator or tendon values of the state, not {self.kind}')
        first = 1 if self.kind == 'body' else 0
        accessor = getattr(model, self.kind)
        names = [accessor(i).name for i in range(first, count)]
        if self.name == '*':
            return names
        if self.name not in names:
            raise ValueError(f"{self.text}: no {self.kind} named {self.name!r}; the model's "
                             f'{_PLURAL.get(self.kind, self.kind + "s")}: '
                             f'{", ".join(names) or "none"}')
        return [self.name]

    def data_read(self, data: mujoco.MjData, names: list[str]) -> np.ndarray:
        """The addressed state values, flattened in element order."""
        accessor = getattr(data, self.kind)
        parts = []
        for name in names:
            view = accessor(name)
            if not hasattr(view, self.attr):
                known = sorted(a for a in dir(view) if not a.startswith('_'))
                raise ValueError(f'{self.text}: the state of a {self.kind} has no {self.attr!r}; '
                                 f'it has: {", ".join(known)}')
            value = np.atleast_1d(np.asarray(getattr(view, self.attr),
                                             dtype=np.float64)).reshape(-1)
            if self.index and max(self.index) >= value.size:
                raise ValueError(f'{self.text}: index {max(self.index)} out of range; '
                                 f'{self.attr} has {value.size} value(s)')
            parts.append(value[list(self.index)] if self.index else value)
        return np.concatenate(parts) if parts else np.zeros(0)


def parse_path(text: str) -> ModelPath:
    """Parse a path; ValueError showing the grammar when it does not match."""
    match = _PATTERN.match(str(text).strip())
    if match is None:
        raise ValueError(f'{text!r} is not a model path; write KIND:NAME.ATTRIBUTE[INDEX] (e.g. '
                         "'geom:floor.friction[0]', 'body:payload.mass', "
                         "'actuator:*.gear[0]') or option.ATTRIBUTE[INDEX] ('option.gravity[2]')")
    index = tuple(int(i) for i in (match['index'] or '').split(',') if i.strip())
    if match['option']:
        return ModelPath(text, 'option', '', match['attr'], index)
    return ModelPath(text, match['kind'], match['name'], match['attr'], index)
