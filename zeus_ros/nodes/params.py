"""Declare a node's parameters with descriptors, validate them, and apply live changes.

One table of `Spec`s per node says each parameter's default, what it means, its range or
choices, and whether it can change while the node runs. The same checks run at start-up (a
ValueError stops the node with one clear line) and for every `ros2 param set` (refused with
the reason); parameters that cannot change live are declared read-only, so ROS refuses them.

Safety-relevant live parameters (`Spec.safety`: the ones that can disarm the loop or blind its
monitoring, e.g. sim_bridge's action_timeout, the policy's noise) are bounded so that no accepted
value turns every step into the safe action, and every accepted live change of one is a WARN
line and a /diagnostics WARN with the old and the new value (`LiveChanges`). rclpy's parameter
service does not tell the callback who called it, so neither line can name the caller. With
`lock_parameters:=true` (`LOCK_SPECS`, set at start only) they are declared read-only, and
ROS refuses every change (docs/security.md).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
import math
import time
from typing import TYPE_CHECKING, Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ['LOCK_PARAMETER', 'LOCK_SPECS', 'ROS_OWN', 'LiveChanges', 'Spec', 'declare_specs',
           'range_text', 'serve_live_changes', 'validate']

ROS_OWN = frozenset({'use_sim_time', 'start_type_description_service'})
"""Parameters rclpy declares on every node."""


@dataclass(frozen=True)
class Spec:
    """One parameter: default (its type is the parameter's type), meaning, limits, liveness."""

    default: Any
    description: str
    live: bool = False
    low: float | None = None
    high: float | None = None
    choices: tuple[Any, ...] = ()
    required: bool = False
    allowed: str = ''
    """What a value may be, in words, where no bound or choice says it all (a file that exists).
    A list parameter's `low` / `high` bound each of its items."""
    safety: bool = False
    """Safety-relevant: a live change is a WARN (log and /diagnostics) with the old and new
    value, and `lock_parameters:=true` makes it read-only."""


LOCK_PARAMETER = 'lock_parameters'
LOCK_SPECS: dict[str, Spec] = {
    LOCK_PARAMETER: Spec(False, 'deployment: declare every safety-relevant parameter read-only, '
                         'so that no process can change it while the node runs (false: they '
                         'stay live, each change a WARN on /diagnostics)'),
}
"""The lock option of every node with safety-relevant live parameters (read-only itself)."""


def _type_name(value: Any) -> str:
    return {bool: 'true/false', int: 'an integer', float: 'a number', str: 'a string'}.get(
        type(value), type(value).__name__)


def _type_ok(default: Any, value: Any) -> bool:
    if isinstance(default, bool):
        return isinstance(value, bool)
    if isinstance(default, (int, float)):
        return isinstance(value, (int, float)) and not isinstance(value, bool) and (
            isinstance(default, float) or isinstance(value, int))
    if isinstance(default, list):
        return isinstance(value, (list, tuple)) or hasattr(value, 'typecode')
    return isinstance(value, type(default))


def range_text(spec: Spec) -> str:
    """The values `spec` allows, in words (`ros2 param describe`, the guide's tables)."""
    if spec.choices:
        return 'one of ' + ', '.join(map(str, spec.choices))
    if isinstance(spec.default, bool):
        text = 'true or false'
    elif spec.low is not None and spec.high is not None:
        text = f'{spec.low} to {spec.high}'
    elif spec.low is not None:
        text = f'>= {spec.low}'
    elif spec.high is not None:
        text = f'<= {spec.high}'
    else:
        text = ''
    if isinstance(spec.default, list) and text:
        text = f'each {text}'
    return '; '.join(part for part in (text, spec.allowed) if part)


def _bounded_items(node_name: str, key: str, spec: Spec, value: Any) -> None:
    """A list parameter with bounds: every item a number of the default's kind, in bounds."""
    for item in value:
        if spec.default and not _type_ok(spec.default[0], item):
            raise ValueError(f'{node_name}: parameter {key} must hold '
                             f'{_type_name(spec.default[0])}s, got {list(value)!r}')
        if (spec.low is not None and item < spec.low) or (
                spec.high is not None and item > spec.high):
            raise ValueError(f'{node_name}: parameter {key} must hold values '
                             f'{range_text(spec).removeprefix("each ")}, got {list(value)!r}')


def validate(node_name: str, specs: Mapping[str, Spec], values: Mapping[str, Any]) -> None:
    """Raise ValueError naming parameter, value and what is allowed, for the first bad value."""
    for key, value in values.items():
        spec = specs[key]
        if not _type_ok(spec.default, value):
            raise ValueError(f'{node_name}: parameter {key} must be {_type_name(spec.default)}, '
                             f'got {value!r}')
        scalar = not isinstance(spec.default, list)
        if not scalar and (spec.low is not None or spec.high is not None):
            _bounded_items(node_name, key, spec, value)
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f'{node_name}: parameter {key} must be a finite number, got {value}')
        if scalar and spec.low is not None and value < spec.low:
            raise ValueError(f'{node_name}: parameter {key} must be >= {spec.low}, got {value}')
        if scalar and spec.high is not None and value > spec.high:
            raise ValueError(f'{node_name}: parameter {key} must be <= {spec.high}, got {value}')
        if spec.choices and value not in spec.choices:
            raise ValueError(f'{node_name}: parameter {key}={value!r} is not allowed; '
                             f'choose one of {", ".join(map(str, spec.choices))}')
        if spec.required and not value:
            raise ValueError(f'{node_name}: parameter {key} is required (e.g. -p {key}:=...)')


def _descriptor(spec: Spec, locked: bool = False) -> ParameterDescriptor:
    """What `ros2 param describe` shows: meaning, limits, and whether a change applies live."""
    live = spec.live and not (locked and spec.safety)
    if spec.live and not live:
        text = spec.description + f' (read-only: {LOCK_PARAMETER} is true)'
    else:
        text = spec.description + ('' if live else ' (read-only: restart the node to change)')
    if live and spec.safety:
        text += f' (safety-relevant: a live change WARNs; {LOCK_PARAMETER}:=true locks it)'
    descriptor = ParameterDescriptor(description=text, read_only=not live)
    if spec.choices or spec.allowed or isinstance(spec.default, list):
        descriptor.additional_constraints = range_text(spec)
    if spec.low is not None or spec.high is not None:
        if isinstance(spec.default, float):
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(spec.low if spec.low is not None else -math.inf),
                to_value=float(spec.high if spec.high is not None else math.inf))]
        elif isinstance(spec.default, int) and not isinstance(spec.default, bool):
            descriptor.integer_range = [IntegerRange(
                from_value=int(spec.low if spec.low is not None else -2**63),
                to_value=int(spec.high if spec.high is not None else 2**63 - 1), step=1)]
    return descriptor


def declare_specs(
    node: Node,
    specs: Mapping[str, Spec],
    *,
    open_prefixes: Iterable[str] = (),
) -> dict[str, Any]:
    """Declare every parameter of `specs` with its descriptor; return the validated values.

    Raises ValueError for an unknown override (a typo would otherwise be silently ignored), a
    wrong type, a value out of range or choices, or an empty required string. Overrides under
    one of `open_prefixes` (free-form groups such as `schedule.`) are declared read-only as given.
    """
    name = node.get_name()
    overrides: dict[str, Parameter] = dict(node._parameter_overrides)
    prefixes = tuple(open_prefixes)
    unknown = sorted(key for key in overrides
                     if key not in specs and key not in ROS_OWN and not key.startswith(prefixes))
    if unknown:
        raise ValueError(f'{name}: unknown parameter(s) {unknown}; known: {sorted(specs)}'
                         + ''.join(f' and {p}*' for p in prefixes))
    values = {key: overrides[key].value if key in overrides else spec.default
              for key, spec in specs.items()}
    validate(name, specs, values)
    locked = bool(values.get(LOCK_PARAMETER, False))
    for key, spec in specs.items():
        if isinstance(spec.default, float) and isinstance(values[key], int):
            values[key] = float(values[key])  # `timeout: 2` means 2.0: accept it as a double
            node._parameter_overrides[key] = Parameter(key, value=values[key])
        try:
            values[key] = node.declare_parameter(key, spec.default,
                                                 _descriptor(spec, locked)).value
        except ParameterException as error:
            raise ValueError(f'{name}: parameter {key}: {error}') from error
    for key, override in overrides.items():
        if prefixes and key.startswith(prefixes):
            node.declare_parameter(key, override.type_, ParameterDescriptor(
                read_only=True, description='part of a free-form group (read-only: restart '
                'the node to change)'))
    return values


class LiveChanges:
    """The accepted live changes of safety-relevant parameters, for the node's /diagnostics.

    A parameter that differs from its value at start is a WARN for as long as it does; one
    changed and set back still WARNs for `window` seconds. Who made the change is not known:
    rclpy's parameter service passes the callback only the parameters, not the caller.
    """

    def __init__(self, specs: Mapping[str, Spec], values: Mapping[str, Any],
                 window: float = 5.0) -> None:
        self.window = window
        self.start = {key: values[key] for key, spec in specs.items() if spec.safety}
        self.now = dict(self.start)
        self.count = 0
        self._recent: list[tuple[float, str, Any, Any]] = []

    def record(self, key: str, old: Any, new: Any) -> None:
        """One accepted change of `key` from `old` to `new`."""
        self.count += 1
        self.now[key] = new
        self._recent.append((time.monotonic(), key, old, new))

    def problems(self) -> list[str]:
        """WARN lines: each parameter off its start value, each change of the last window."""
        cutoff = time.monotonic() - self.window
        self._recent = [change for change in self._recent if change[0] >= cutoff]
        lines = [f'{key} changed live: {self.start[key]!r} at start, now {value!r} '
                 f'(caller unknown; {LOCK_PARAMETER}:=true refuses changes)'
                 for key, value in self.now.items() if value != self.start[key]]
        lines += [f'{key} changed live {old!r} -> {new!r} {time.monotonic() - at:.0f} s ago '
                  '(caller unknown)' for at, key, old, new in self._recent
                  if self.now[key] == self.start[key]]
        return lines

    def values(self) -> dict[str, Any]:
        """/diagnostics values: how many live changes, and whether the parameters are locked."""
        return {'safety_param_changes': self.count}


def serve_live_changes(
    node: Node,
    specs: Mapping[str, Spec],
    values: dict[str, Any],
    apply: Callable[[dict[str, Any]], None],
    check: Callable[[dict[str, Any]], None] | None = None,
    prepare: Callable[[dict[str, Any]], None] | None = None,
) -> LiveChanges:
    """Validate `ros2 param set` like start-up; on success update `values` and call `apply`.

    `check(all_values)` runs the node's own cross-parameter checks (raise ValueError);
    `prepare(changed)` then does the work a change needs before it can be accepted (loading a
    checkpoint: raise ValueError to refuse); `apply` gets only the changed values, after they
    were accepted. A refusal carries the reason. Each accepted change of a safety-relevant
    parameter is a WARN line with the old and the new value, and recorded in the returned
    `LiveChanges` for the node's /diagnostics.
    """
    name = node.get_name()
    locked = bool(values.get(LOCK_PARAMETER, False))
    changes = LiveChanges(specs, values)

    def on_set(parameters: list[Parameter]) -> SetParametersResult:
        changed = {p.name: p.value for p in parameters if p.name not in ROS_OWN}
        for key in changed:
            if key not in specs:
                return SetParametersResult(successful=False, reason=f'{name}: unknown or '
                                           f'read-only parameter {key}; known: {sorted(specs)}')
            if not specs[key].live:
                return SetParametersResult(
                    successful=False, reason=f'{name}: parameter {key} is read-only')
            if locked and specs[key].safety:
                return SetParametersResult(
                    successful=False, reason=f'{name}: parameter {key} is read-only '
                    f'({LOCK_PARAMETER} is true)')
        try:
            validate(name, specs, changed)
            if check is not None:
                check({**values, **changed})
            if prepare is not None:
                prepare(changed)
        except ValueError as error:
            node.get_logger().warning(f'refused a live parameter change: {error}')
            return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    def after_set(parameters: list[Parameter]) -> None:
        changed = {p.name: p.value for p in parameters if p.name in specs}
        if not changed:
            return
        old = {key: values[key] for key in changed}
        values.update(changed)
        apply(changed)
        for key, value in changed.items():
            if specs[key].safety:
                changes.record(key, old[key], value)
                node.get_logger().warning(
                    f'safety-relevant parameter {key} changed live: {old[key]!r} -> {value!r} '
                    f'(by a parameter service call; the caller is not known: set '
                    f'{LOCK_PARAMETER}:=true to refuse such changes)')
        rest = {key: value for key, value in changed.items() if not specs[key].safety}
        if rest:
            node.get_logger().info(f'parameters changed live: {rest}')

    node.add_on_set_parameters_callback(on_set)
    node.add_post_set_parameters_callback(after_set)
    return changes
