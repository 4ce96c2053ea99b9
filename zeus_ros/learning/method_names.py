"""The shipped method names, without their objectives (no torch).

A command line lists them as `--method` choices before it imports anything heavy, so that
`zeus train --help` answers at once (issue 52). learning/methods.py refuses to import when its
registry and this tuple disagree, so a new method cannot be added to one and not the other.
"""

from __future__ import annotations

__all__ = ['METHOD_NAMES']

METHOD_NAMES: tuple[str, ...] = ('zeus', 'zeus_no_context_loss', 'no_context', 'up_osi', 'cadm',
                                 'oracle', 'oracle_sac')
"""The method names in table order: the keys of learning/methods.METHOD_REGISTRY."""
