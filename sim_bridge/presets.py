"""The preset splits of every task family, and where the families' files live.

The value lists themselves are part of each family's declaration (sim_bridge/families.py):
`params/tasks/<Task>.yaml` for the built-in families, `presets:` in a user's task file; read
one with `sim_bridge.families.load_preset`. This module imports no other sim_bridge module, so
the task modules and the families can both read the split names without an import circle.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ['SPLITS', 'find_params_dir']

SPLITS = ('train', 'interpolation', 'extrapolation')
"""The preset splits, in order: the one definition every tool uses."""


def find_params_dir() -> Path:
    """The params/ directory: this checkout, else share/zeus_ros/params of an ament prefix."""
    candidates = [Path(__file__).resolve().parents[1] / 'params']
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            candidates.append(Path(prefix) / 'share' / 'zeus_ros' / 'params')
    for candidate in candidates:
        if (candidate / 'tasks').is_dir():
            return candidate
    raise FileNotFoundError(
        'no params/tasks directory found; looked in ' + ', '.join(map(str, candidates)))

