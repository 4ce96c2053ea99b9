"""The import contract: which room of the house may use which (issue 39).

The import graph of zeus_ros/ and sim_bridge/ is read from the source (every import, also those
inside functions and under TYPE_CHECKING: a lazy import is still a dependency), and these rules
hold on it:

- no import circle;
- offline/ layers strictly: training/ over evaluation/ over the shared rollout.py and runs.py,
  over data/; nothing below imports what is above it;
- the live nodes (nodes/) import nothing from offline/, the continual trainer included (it runs
  each training round in a child process, `zeus continual-round`); offline/ imports nothing
  from nodes/;
- the learning core (learning/), the simulator (sim_bridge/) and the bag format (bags/) import
  nothing from nodes/, offline/ or the command line (cli/);
- ROS (rclpy, message packages, rosbag2_py, rosidl, ament, launch) is imported only in nodes/
  and the live tools named in LIVE_TOOLS;
- every command line lives in cli/ (one module per command, `zeus launch`, `zeus inspect` and
  `zeus demo` included): nothing else imports cli/, and no module outside cli/ and the node
  executables of nodes/ defines a `main` (the libraries offline/, learning/, bags/,
  sim_bridge/, the live system's system/, the top-level utilities);
- what runs the live system (the node plan and its defaults, processes, respawn, progress)
  lives in system/, which imports nothing from offline/;
- the top of zeus_ros/ holds only the shared utilities named in TOP_LEVEL_UTILITIES: a new
  module goes into its room (cli/, system/, nodes/, offline/, learning/, bags/).
"""

from __future__ import annotations

import ast
from collections.abc import Iterable
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ('zeus_ros', 'sim_bridge')

LIVE_TOOLS = frozenset({
    'zeus_ros.cli.inspect_topics',  # `zeus inspect`: subscribes to the context topics
    'zeus_ros.system.launch_progress',  # `zeus launch`: watches the nodes come up
    'zeus_ros.system.processes',  # starts and stops the node processes, waits for the graph
    'zeus_ros.system.launch_defaults',  # the package share via ament_index (optional import)
})
"""Modules outside nodes/ that may import ROS: the tools that talk to a running graph."""

LIBRARIES = ('zeus_ros.offline', 'zeus_ros.learning', 'zeus_ros.bags', 'sim_bridge')

WITH_MAIN = ('zeus_ros.cli', 'zeus_ros.nodes')
"""Where a `main` may be: the commands, and the node executables (console scripts)."""

TOP_LEVEL_UTILITIES = frozenset({
    'zeus_ros.atomic_file',  # the one atomic write
    'zeus_ros.cli_args',  # argument types and errors; input_path is also read by training
    'zeus_ros.config_sets',  # --set KEY=VALUE on a config; also the sweep's grids
    'zeus_ros.gym_env',  # the zeus_ros/<task> Gymnasium registrations
    'zeus_ros.integrity',  # checkpoints' recorded sha256: load_checkpoint, zeus launch; no torch
    'zeus_ros.labels',  # task and context labels for tables and plots
    'zeus_ros.step_log',  # per-step records, context segments, plots (inspect, demo)
    'zeus_ros.yaml_text',  # a user's YAML file, with a one-line error saying where
})
"""The modules at the top of zeus_ros/: utilities shared by several rooms, no command, no ROS."""

_ROS_TOP_LEVEL = frozenset({'rclpy', 'rosbag2_py', 'ament_index_python', 'launch',
                            'launch_ros', 'launch_testing', 'message_filters', 'rmw',
                            'rpyutils', 'tf2_ros', 'ros2cli'})
_ROS_SUFFIXES = ('_msgs', '_srvs', '_interfaces')


def is_ros(module: str) -> bool:
    """True for a ROS 2 Python package (rosbags, the pure-Python bag library, is not one)."""
    top = module.split('.')[0]
    return (top in _ROS_TOP_LEVEL or top.startswith('rosidl')
            or top.endswith(_ROS_SUFFIXES))


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def _imported(tree: ast.AST, package: str) -> Iterable[str]:
    """Every module named by an import statement anywhere in `tree` (relative ones resolved)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parts = package.split('.')[:len(package.split('.')) - node.level + 1]
                base = '.'.join([*parts, *([base] if base else [])])
            yield base
            yield from (f'{base}.{alias.name}' for alias in node.names)


@cache
def import_graph() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """(project module -> project modules it imports, project module -> other modules)."""
    files = {_module_name(f): f for package in PACKAGES for f in (ROOT / package).rglob('*.py')}
    inside: dict[str, set[str]] = {name: set() for name in files}
    outside: dict[str, set[str]] = {name: set() for name in files}
    for name, path in files.items():
        package = name if path.name == '__init__.py' else name.rpartition('.')[0]
        for target in _imported(ast.parse(path.read_text(encoding='utf-8')), package):
            if target.split('.')[0] not in PACKAGES:
                outside[name].add(target)
                continue
            known = target
            while known and known not in files:  # `from pkg import name`: name is no module
                known = known.rpartition('.')[0]
            if known and known != name and not name.startswith(known + '.'):
                inside[name].add(known)
    return inside, outside


def _edges(source: str, target: str) -> list[str]:
    """Imports from modules under `source` into modules under `target` (prefixes)."""
    inside, _ = import_graph()
    return sorted(f'{module} -> {imported}' for module, targets in inside.items()
                  if _under(module, source) for imported in targets if _under(imported, target))


def _under(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + '.')


def circles() -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan, iterative)."""
    graph, _ = import_graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, successors = work[-1]
            for successor in successors:
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(sorted(graph[successor]))))
                    break
                if successor in on_stack:
                    low[node] = min(low[node], index[successor])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    group = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        group.append(member)
                        if member == node:
                            break
                    if len(group) > 1:
                        found.append(sorted(group))
    return found


def test_the_graph_is_read() -> None:
    """The contract below is checked on the whole tree (a broken reader would pass anything)."""
    inside, outside = import_graph()
    assert len(inside) > 100
    assert 'zeus_ros.learning.agent' in inside['zeus_ros.learning.checkpoint']
    assert 'rclpy' in {m.split('.')[0] for m in outside['zeus_ros.nodes.policy_node']}
    assert _edges('zeus_ros.offline.training', 'zeus_ros.offline.rollout')


def test_no_import_circles() -> None:
    """Every module can be understood (and imported) after the modules it uses."""
    assert circles() == []


def test_offline_layers() -> None:
    """training/ over evaluation/ over rollout.py + runs.py over data/; never upwards."""
    offline = 'zeus_ros.offline'
    training, evaluation, data = (f'{offline}.training', f'{offline}.evaluation',
                                  f'{offline}.data')
    shared = (f'{offline}.rollout', f'{offline}.runs')
    below_above = [(evaluation, training), (data, training), (data, evaluation),
                   *((data, module) for module in shared),
                   *((module, above) for module in shared for above in (training, evaluation))]
    assert [edge for below, above in below_above for edge in _edges(below, above)] == []


def test_nodes_and_offline_stay_apart() -> None:
    """The live nodes load, act and record without the offline tools, no exception.

    The continual trainer too: its rounds run in `zeus continual-round` (a child process); the
    node's own pieces (settings, history, live checks, closed splits) are in system/ and bags/.
    """
    assert _edges('zeus_ros.nodes', 'zeus_ros.offline') == []
    assert _edges('zeus_ros.offline', 'zeus_ros.nodes') == []
    inside, _ = import_graph()
    assert not any(_under(module, 'zeus_ros.offline')
                   for module in inside['zeus_ros.nodes.continual_node'])


def test_the_core_imports_no_tools() -> None:
    """learning/, sim_bridge/ and bags/ import neither nodes/, offline/ nor cli/."""
    for core in ('zeus_ros.learning', 'sim_bridge', 'zeus_ros.bags'):
        for tools in ('zeus_ros.nodes', 'zeus_ros.offline', 'zeus_ros.cli'):
            assert _edges(core, tools) == [], (core, tools)


def test_ros_only_in_nodes_and_live_tools() -> None:
    """The learning core, the simulator and the offline tools run where ROS is not installed."""
    _, outside = import_graph()
    misplaced = sorted(f'{module} imports {name}' for module, names in outside.items()
                       for name in names if is_ros(name)
                       and not _under(module, 'zeus_ros.nodes') and module not in LIVE_TOOLS)
    assert misplaced == []


def test_commands_live_in_one_wing() -> None:
    """cli/ reads arguments and calls libraries; no library parses a command line itself."""
    assert [edge for edge in _edges('zeus_ros', 'zeus_ros.cli')
            if not _under(edge.split(' -> ')[0], 'zeus_ros.cli')] == []
    with_main = sorted(
        _module_name(path) for package in PACKAGES for path in (ROOT / package).rglob('*.py')
        if not any(_under(_module_name(path), room) for room in WITH_MAIN)
        and any(isinstance(node, ast.FunctionDef) and node.name == 'main'
                for node in ast.parse(path.read_text(encoding='utf-8')).body))
    assert with_main == []
    assert not any(_under(module, room) for module in with_main for room in LIBRARIES)


def test_the_live_system_is_one_room() -> None:
    """system/ (plan, processes, respawn, progress) runs the nodes, never the offline tools."""
    inside, _ = import_graph()
    assert {'zeus_ros.system.launch_defaults', 'zeus_ros.system.processes',
            'zeus_ros.system.respawn', 'zeus_ros.system.launch_progress'} <= set(inside)
    assert _edges('zeus_ros.system', 'zeus_ros.offline') == []


def test_the_top_level_holds_only_utilities() -> None:
    """zeus_ros/*.py: the shared utilities, no command, no launch plumbing, no ROS."""
    _, outside = import_graph()
    top = {_module_name(path) for path in (ROOT / 'zeus_ros').glob('*.py')} - {'zeus_ros'}
    assert top == TOP_LEVEL_UTILITIES
    assert sorted(f'{module} imports {name}' for module in top for name in outside[module]
                  if is_ros(name)) == []


def test_the_rules_catch_what_they_forbid() -> None:
    """The checks themselves: a circle and a ROS import are seen."""
    assert is_ros('rclpy.node') and is_ros('zeus_msgs.msg') and is_ros('rosidl_parser')
    assert not is_ros('rosbags.typesys') and not is_ros('numpy')
    tree = ast.parse('from . import b\nfrom ..c import d\nimport e.f\n')
    assert list(_imported(tree, 'p.q')) == ['p.q', 'p.q.b', 'p.c', 'p.c.d', 'e.f']
