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


def declare_and_validate(
    node: Node,
    defaults: Mapping[str, Any],
    *,
    required: Iterable[str] = (),
    choices: Mapping[str, Iterable[Any]] | None = None,
    nonnegative: bool = True,
) -> dict[str, Any]:
    """Declare every parameter with its default and return the validated values.

    Raises ValueError naming the node, the parameter, what was given and what is allowed: a
    wrong type, a negative number, a value outside `choices`, or an empty required string.
    """
    name = node.get_name()
    values: dict[str, Any] = {}
    for key, default in defaults.items():
        try:
            parameter = node.declare_parameter(key, default)
        except (InvalidParameterTypeException, ParameterException) as error:
            raise ValueError(
                f'{name}: parameter {key} must be {_type_name(default)} '
                f'(default {default!r}): {error}') from error
        values[key] = parameter.value
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
