"""`--set KEY=VALUE`: any training-config field from the command line, validated like the file.

One parser for `zeus train`, `zeus loop` (one value per field) and `zeus sweep` (several
comma-separated values make a grid axis). Values are read as YAML scalars (`k=7` is an int,
`alpha_psi=auto` a string, `critic_context_grad=false` a bool) and the resulting config is built
by the same ZeusConfig validation as a config file, so a bad value fails the same way.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
import dataclasses
from functools import cache
from typing import TYPE_CHECKING, Any

import yaml

from zeus_ros.cli_args import nearest
from zeus_ros.learning.errors import ConfigError

if TYPE_CHECKING:
    from zeus_ros.learning.config import ZeusConfig

__all__ = ['SET_HELP', 'apply_sets', 'parse_set', 'parse_set_grid', 'parse_sets', 'refuse_both',
           'set_items']

SET_HELP = ('override training-config fields, e.g. --set k=7 batch_size=256 (YAML values, '
            'validated like the config file)')


@cache
def config_fields() -> tuple[str, ...]:
    """The training-config field names (learning/config.py: torch, so read on first use)."""
    from zeus_ros.learning.config import ZeusConfig

    return tuple(field.name for field in dataclasses.fields(ZeusConfig))


def parse_set(item: str, *, flag: str = '--set', grid: bool = False) -> tuple[str, list[Any]]:
    """'k=7' -> ('k', [7]); with grid, 'k=3,5' -> ('k', [3, 5]). ConfigError names the item."""
    key, sep, text = (part.strip() for part in item.partition('='))
    example = 'alpha_psi=0.5,1.0' if grid else 'batch_size=256'
    if not sep or not key or not text:
        raise ConfigError(f'{flag} {item}: expected KEY=VALUE{"[,VALUE...]" if grid else ""}, '
                          f'e.g. {example}')
    fields = config_fields()
    if key not in fields:
        raise ConfigError(f"{flag} {item}: unknown config field '{key}'{nearest(key, fields)} "
                          '(the fields are the keys of params/train/state_cpu.yaml)')
    texts = text.split(',') if grid else [text]
    try:
        values = [yaml.safe_load(part) for part in texts]
    except yaml.YAMLError:
        raise ConfigError(f'{flag} {item}: {text!r} is not a YAML scalar') from None
    if any(isinstance(value, dict | list) for value in values):
        raise ConfigError(f'{flag} {item}: {key} takes one scalar value, got {text!r}')
    return key, values


def _collect(items: Iterable[str], flag: str, grid: bool) -> dict[str, list[Any]]:
    axes: dict[str, list[Any]] = {}
    for item in items:
        key, values = parse_set(item, flag=flag, grid=grid)
        if key in axes:
            more = '; give its values as one comma-separated list' if grid else ''
            raise ConfigError(f'{flag} {item}: {key} is set twice{more}')
        axes[key] = values
    return axes


def parse_sets(items: Iterable[str], flag: str = '--set') -> dict[str, Any]:
    """['k=7', 'batch_size=256'] -> {'k': 7, 'batch_size': 256} (each field once)."""
    return {key: values[0] for key, values in _collect(items, flag, grid=False).items()}


def parse_set_grid(items: Iterable[str], flag: str = '--set') -> dict[str, list[Any]]:
    """['k=3,5', 'j=c'] -> {'k': [3, 5], 'j': ['c']}: one grid axis per field."""
    return _collect(items, flag, grid=True)


def apply_sets(config: ZeusConfig, sets: dict[str, Any], flag: str = '--set') -> ZeusConfig:
    """`config` with `sets` applied, validated as a config file would be (ConfigError if not)."""
    if not sets:
        return config
    from zeus_ros.learning.config import config_from_dict

    source = f'{flag} ' + ' '.join(f'{key}={_show(value)}' for key, value in sets.items())
    return config_from_dict({**config.to_dict(), **sets}, source=source)


def set_items(sets: dict[str, Any]) -> list[str]:
    """{'k': 7} -> ['k=7']: the command-line spelling, for stored flags and messages."""
    return [f'{key}={_show(value)}' for key, value in sets.items()]


def _show(value: Any) -> str:
    text = yaml.safe_dump(value, default_flow_style=True).strip()
    return text.removesuffix('\n...').removesuffix('...').strip()


def refuse_both(sets: dict[str, Any], flags: Sequence[tuple[str, str, Any]],
                flag: str = '--set') -> None:
    """A field given both by --set and by its own flag (--updates, --seed...) is ambiguous."""
    for field_name, own_flag, value in flags:
        if value is not None and field_name in sets:
            raise ConfigError(f'{flag} {field_name}={_show(sets[field_name])} and {own_flag} '
                              f'{value} both set {field_name}; give one')
