"""How figures and tables name things: one spelling of task names, context parameters with units.

Run folders spell a task `cheetah_run_v0`; every title and legend spells it `Cheetah-Run-v0`,
the name `--task` takes. Context axes carry the unit the task's ContextSpec documents.
"""

from __future__ import annotations

from functools import cache
import re

__all__ = ['context_label', 'context_unit', 'task_label']


def task_label(name: str) -> str:
    """The registered spelling of a task name in a folder name.

    'finger_spin_v0' -> 'Finger-Spin-v0', 'cheetah_run_v0_10k' -> 'Cheetah-Run-v0 10k';
    a name without a task is returned as it is.
    """
    from sim_bridge.registry import TASK_NAMES

    key = name.lower().replace('-', '_')
    for task in TASK_NAMES:
        slug = task.lower().replace('-', '_')
        if key == slug or key.startswith(slug + '_'):
            rest = name[len(slug):].replace('_', ' ').strip()
            return f'{task} {rest}'.strip()
    return name


@cache
def _units() -> dict[str, str]:
    """Context parameter -> unit, from the `[unit]` in each task's ContextSpec doc."""
    from sim_bridge.registry import TASK_NAMES, task_class

    units: dict[str, str] = {}
    for task in TASK_NAMES:
        try:
            specs = getattr(task_class(task), 'specs', ())
        except ValueError:  # a task whose dependencies are missing here
            continue
        for spec in specs:
            match = re.search(r'\[([^\]]+)\]', spec.doc)
            units.setdefault(spec.name, match.group(1) if match else '')
    return units


def context_unit(name: str) -> str:
    """The unit of a context parameter ('' when dimensionless or unknown)."""
    return _units().get(name, '')


def context_label(name: str, prefix: str = '') -> str:
    """An axis label for a context parameter: 'torso_length [m]', 'friction' (no unit)."""
    unit = context_unit(name)
    text = f'{prefix}{name}'
    return f'{text} [{unit}]' if unit else text
