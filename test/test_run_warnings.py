"""A run that guesses or lacks something says so in one line (issue 52, item 4).

`alpha_psi: auto` on a family that declares no training defaults (a user's own task file) was
silently 1.0, the value that saturates psi on the Cheetah dynamics families; a run on fewer
transitions than seed_steps went ahead without a word.
"""

from __future__ import annotations

from pathlib import Path

from sim_bridge.registry import register_task_file
from zeus_ros.learning.config import ZeusConfig, resolve_config, undeclared_defaults
from zeus_ros.offline.training.train import run_warnings

PAYLOAD = Path(__file__).resolve().parents[1] / 'params' / 'tasks' / 'payload_point_mass.yaml'
"""The shipped example task file: no `training:` section."""


def test_auto_on_an_undeclared_family_is_named_with_its_value_and_why() -> None:
    """One line: the value auto took, that the file declares none, and how to declare it."""
    task = register_task_file(PAYLOAD)
    note = undeclared_defaults(ZeusConfig(method='zeus'), task)
    assert note is not None and '\n' not in note
    chosen = resolve_config(ZeusConfig(method='zeus'), task).alpha_psi
    assert f'alpha_psi auto -> {chosen} for {task}' in note
    assert str(PAYLOAD) in note and 'declares no' in note
    assert 'saturates psi' in note and '--set alpha_psi=' in note


def test_declared_given_or_unused_alpha_psi_says_nothing() -> None:
    """A built-in family declares it; a number is a choice; no_context never reads it."""
    task = register_task_file(PAYLOAD)
    assert undeclared_defaults(ZeusConfig(method='zeus'), 'Cheetah-Bias-v0') is None
    assert undeclared_defaults(ZeusConfig(method='zeus', alpha_psi=0.5), task) is None
    for method in ('no_context', 'zeus_no_context_loss', 'oracle'):
        assert undeclared_defaults(ZeusConfig(method=method), task) is None, method


def test_fewer_transitions_than_seed_steps_is_one_line() -> None:
    """390 transitions with seed_steps 1500: said, with both numbers and the way out."""
    config = ZeusConfig(method='zeus', alpha_psi=1.0, seed_steps=1500)
    [line] = run_warnings(config, 'Cheetah-Bias-v0', 390)
    assert '390 transitions' in line and 'seed_steps 1500' in line and '\n' not in line
    assert run_warnings(config, 'Cheetah-Bias-v0', 1500) == []


def test_both_warnings_on_a_small_run_of_an_undeclared_family() -> None:
    """What `zeus train` logs for the issue's run: the auto value, then the short data."""
    task = register_task_file(PAYLOAD)
    lines = run_warnings(ZeusConfig(method='zeus', seed_steps=1500), task, 390)
    assert len(lines) == 2 and lines[0].startswith('alpha_psi auto') and '390' in lines[1]
