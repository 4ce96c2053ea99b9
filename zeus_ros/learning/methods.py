"""The method registry: method name -> its objective (learning/objectives/<method>.py).

The agent, config validation, the CLI choices, the cards and the report order all read this
table, so a new training objective is one new module under objectives/ plus one line here.
Nothing outside the objectives compares method names: ask the objective instead
(`method_objective(name).needs_pair(config)`, `.context_source`, `.models`, `.reads(option)`).
"""

from __future__ import annotations

from zeus_ros.learning.method_names import METHOD_NAMES
from zeus_ros.learning.objectives.base import Objective
from zeus_ros.learning.objectives.cadm import Cadm
from zeus_ros.learning.objectives.no_context import NoContext
from zeus_ros.learning.objectives.oracle import Oracle, OracleSac
from zeus_ros.learning.objectives.up_osi import UpOsi
from zeus_ros.learning.objectives.zeus import Zeus, ZeusNoContextLoss

__all__ = ['METHODS', 'METHOD_REGISTRY', 'method_objective']

METHOD_REGISTRY: dict[str, Objective] = {objective.name: objective for objective in (
    Zeus(),
    ZeusNoContextLoss(),
    NoContext(),
    UpOsi(),
    Cadm(),
    Oracle(),
    OracleSac(),
)}
"""Every method, in the order tables list them."""

METHODS = tuple(METHOD_REGISTRY)
"""The shipped method names, in table order (a test may register more in METHOD_REGISTRY)."""
if METHODS != METHOD_NAMES:  # the torch-free copy the command lines offer as choices
    raise ImportError(f'learning/method_names.py lists {METHOD_NAMES}, the registry {METHODS}: '
                      'give a new method in both')


def method_objective(name: str) -> Objective:
    """The objective of method `name` (ValueError listing the methods when unknown)."""
    try:
        return METHOD_REGISTRY[name]
    except KeyError:
        raise ValueError(f'unknown method {name!r}; methods: '
                         f'{", ".join(METHOD_REGISTRY)}') from None
