"""Read a YAML file a user named, with a one-line error that says where it is wrong.

One loader for every params file a node or a launcher reads ahead of rcl (`ParamsLoader`):
launch_ros writes each node's parameter dict with `yaml.dump`, so list parameters come out
tagged `!!python/tuple`. rcl reads such a file (it ignores the tags), so the nodes must too:
a python tag is read as the plain YAML it tags, never constructed as a Python object.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

__all__ = ['ParamsLoader', 'YamlTextError', 'load_yaml_text', 'safe_load_params']

PYTHON_TAG = 'tag:yaml.org,2002:python/'
"""The prefix of PyYAML's Python tags (!!python/tuple, !!python/str, ...)."""


class ParamsLoader(yaml.SafeLoader):
    """yaml.SafeLoader that reads a `!!python/...` tag as the untagged node: rcl's reading.

    A sequence (`!!python/tuple`, what launch_ros writes for a list) is a list, a mapping a
    dict, a scalar what the same text without the tag is. Nothing is imported or called
    (unlike yaml.unsafe_load), so a params file still cannot run code.
    """


def _construct_untagged(loader: ParamsLoader, _suffix: str, node: yaml.Node) -> Any:
    """The value of `node` as if it had no tag (rcl's parser ignores tags)."""
    if isinstance(node, yaml.SequenceNode):
        return loader.construct_sequence(node, deep=True)
    if isinstance(node, yaml.MappingNode):
        return loader.construct_mapping(node, deep=True)
    plain = yaml.ScalarNode(loader.resolve(yaml.ScalarNode, node.value, (True, False)),
                            node.value, node.start_mark, node.end_mark, node.style)
    return loader.construct_object(plain, deep=True)


ParamsLoader.add_multi_constructor(PYTHON_TAG, _construct_untagged)


def safe_load_params(text: str) -> Any:
    """`yaml.safe_load` that also reads launch_ros's tagged params files (ParamsLoader)."""
    return yaml.load(text, Loader=ParamsLoader)  # a SafeLoader: builds no Python objects


class YamlTextError(ValueError):
    """The file is not UTF-8 text (`binary` True) or not valid YAML; the message says where."""

    def __init__(self, message: str, *, binary: bool) -> None:
        super().__init__(message)
        self.binary = binary


def load_yaml_text(path: Path) -> Any:
    """The parsed YAML of `path` (None when empty); OSError passes through unchanged.

    Parsed with ParamsLoader: a params file launch_ros wrote reads as rcl reads it.
    """
    try:
        text = Path(path).read_bytes().decode('utf-8')
    except UnicodeDecodeError as error:
        raise YamlTextError(f'not a text file (byte {error.object[error.start]:#04x} at offset '
                            f'{error.start} is not UTF-8)', binary=True) from None
    try:
        return safe_load_params(text)
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        at = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        raise YamlTextError(f'not valid YAML{at}: {getattr(error, "problem", None) or error}',
                            binary=False) from None
