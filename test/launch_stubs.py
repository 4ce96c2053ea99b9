"""The installed zeus.launch.py with launch / launch_ros stubbed (not on PyPI): its actions."""

from __future__ import annotations

import importlib.util
import sys
import types
from typing import Any

import pytest


class Recorded:
    """A launch action or event stand-in: keeps what it was built with."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args, self.kwargs = args, kwargs


class LaunchConfiguration(Recorded):
    """Reads the argument from the dict the test passes as the launch context."""

    def perform(self, context: dict[str, str]) -> str:
        """The argument's value."""
        return context[self.args[0]]


def stub_launch_modules(monkeypatch: pytest.MonkeyPatch) -> None:
    """Minimal stand-ins for launch and launch_ros: record the calls."""
    modules: dict[str, dict[str, Any]] = {
        'launch': {'LaunchContext': dict, 'LaunchDescription': lambda entities: entities},
        'launch.actions': {name: type(name, (Recorded,), {}) for name in (
            'DeclareLaunchArgument', 'EmitEvent', 'ExecuteProcess', 'LogInfo', 'OpaqueFunction',
            'RegisterEventHandler')},
        'launch.event_handlers': {'OnProcessExit': Recorded},
        'launch.events': {'Shutdown': Recorded},
        'launch.substitutions': {'LaunchConfiguration': LaunchConfiguration},
        'launch_ros': {},
        'launch_ros.actions': {'Node': type('Node', (Recorded,), {})},
    }
    for name, attributes in modules.items():
        module = types.ModuleType(name)
        module.__dict__.update(attributes)
        monkeypatch.setitem(sys.modules, name, module)


def installed_launch_file(monkeypatch: pytest.MonkeyPatch) -> types.ModuleType:
    """The installed share/zeus_ros/launch/zeus.launch.py, imported over the stubs."""
    from zeus_ros.system import launch_defaults as d

    stub_launch_modules(monkeypatch)
    installed = d.share_dir() / 'launch' / 'zeus.launch.py'
    spec = importlib.util.spec_from_file_location('zeus_launch_file', installed)
    assert spec is not None and spec.loader is not None
    launch_file = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(launch_file)
    return launch_file


def installed_launch_description(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """The actions of the installed zeus.launch.py: the declared arguments, then the opaque."""
    return list(installed_launch_file(monkeypatch).generate_launch_description())


def launch_actions(monkeypatch: pytest.MonkeyPatch, **arguments: str) -> list[Any]:
    """What the launch file starts for `arguments` (name:=value; the rest default)."""
    *declared, opaque = installed_launch_description(monkeypatch)
    context = {**{a.args[0]: a.kwargs['default_value'] for a in declared}, **arguments}
    return list(opaque.kwargs['function'](context))
