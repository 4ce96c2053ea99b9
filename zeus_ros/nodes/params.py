"""Declare a node's parameters with defaults and validate them with errors a user can act on."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any

from rclpy.exceptions import InvalidParameterTypeException, ParameterException

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ['declare_and_validate']


def _type_name(value: Any) -> str:
    return {bool: 'true/false', int: 'an integer', float: 'a number', str: 'a string'}.get(
        type(value), type(value).__name__)


ROS_OWN = frozenset({'use_sim_time', 'start_type_description_service'})
"""Parameters rclpy declares on every node."""


def _check_type(node_name: str, key: str, default: Any, value: Any) -> None:
    """A value that arrived through automatic declaration must still have the default's type."""
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, (int, float)):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    else:
        ok = isinstance(value, type(default))
    if not ok:
        raise ValueError(f'{node_name}: parameter {key} must be {_type_name(default)}, '
                         f'got {value!r}')


def declare_and_validate(
    node: Node,
    defaults: Mapping[str, Any],
    *,
    required: Iterable[str] = (),
    choices: Mapping[str, Iterable[Any]] | None = None,
    nonnegative: bool = True,
    open_prefixes: Iterable[str] | None = None,
) -> dict[str, Any]:
    """Declare every parameter with its default and return the validated values.

    Raises ValueError naming the node, the parameter, what was given and what is allowed: a
    wrong type, a negative number, a value outside `choices`, or an empty required string.
    A node built with `automatically_declare_parameters_from_overrides` passes the prefixes of
    the free-form groups it accepts (e.g. `schedule.`) as `open_prefixes`; any other unknown
    override is then an error instead of being silently ignored.
    """
    name = node.get_name()
    values: dict[str, Any] = {}
    for key, default in defaults.items():
        if node.has_parameter(key):  # declared from an override already
            values[key] = node.get_parameter(key).value
            _check_type(name, key, default, values[key])
            continue
        try:
            parameter = node.declare_parameter(key, default)
        except (InvalidParameterTypeException, ParameterException) as error:
            raise ValueError(
                f'{name}: parameter {key} must be {_type_name(default)} '
                f'(default {default!r}): {error}') from error
        values[key] = parameter.value
    if open_prefixes is not None:
        prefixes = tuple(open_prefixes)
        unknown = sorted(key for key in node._parameters
                         if key not in defaults and key not in ROS_OWN
                         and not key.startswith(prefixes))
        if unknown:
            raise ValueError(f'{name}: unknown parameter(s) {unknown}; known: '
                             f'{sorted(defaults)}' + ''.join(f' and {p}*' for p in prefixes))
    for key, value in values.items():
        default = defaults[key]
        if isinstance(default, (int, float)) and not isinstance(default, bool) and nonnegative \
                and value < 0:
            raise ValueError(f'{name}: parameter {key} must be >= 0, got {value}')
    for key, allowed in (choices or {}).items():
        allowed = tuple(allowed)
        if values[key] not in allowed:
            raise ValueError(f'{name}: parameter {key}={values[key]!r} is not allowed; '
                             f'choose one of {", ".join(map(str, allowed))}')
    for key in required:
        if not values[key]:
            raise ValueError(f'{name}: parameter {key} is required (e.g. -p {key}:=...)')
    return values
