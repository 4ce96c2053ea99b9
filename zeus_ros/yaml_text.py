"""Read a YAML file a user named, with a one-line error that says where it is wrong."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

__all__ = ['YamlTextError', 'load_yaml_text']


class YamlTextError(ValueError):
    """The file is not UTF-8 text (`binary` True) or not valid YAML; the message says where."""

    def __init__(self, message: str, *, binary: bool) -> None:
        super().__init__(message)
        self.binary = binary


def load_yaml_text(path: Path) -> Any:
    """The parsed YAML of `path` (None when empty); OSError passes through unchanged."""
    try:
        text = Path(path).read_bytes().decode('utf-8')
    except UnicodeDecodeError as error:
        raise YamlTextError(f'not a text file (byte {error.object[error.start]:#04x} at offset '
                            f'{error.start} is not UTF-8)', binary=True) from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        at = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        raise YamlTextError(f'not valid YAML{at}: {getattr(error, "problem", None) or error}',
                            binary=False) from None
