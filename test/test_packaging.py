"""package.xml covers what the code imports: a ROS user's rosdep (plus one pip step) suffices."""

from __future__ import annotations

import ast
import re
import sys

from ros_harness import REPO

IMPORT_TO_DEPENDENCY = {
    'numpy': 'python3-numpy',
    'yaml': 'python3-yaml',
    'ruamel': 'python3-ruamel.yaml',
    'scipy': 'python3-scipy',
    'tqdm': 'python3-tqdm',
    'matplotlib': 'python3-matplotlib',
    'torch': 'python3-torch',
    'mujoco': 'python3-mujoco-pip',
    'rosbags': 'python3-rosbags-pip',
}
"""Third-party Python imports and their rosdep keys."""
PIP_ONLY = {'dm_control': 'dm-control', 'gymnasium': 'gymnasium', 'ray': 'ray'}
"""Imports without a rosdep key: README's pip step installs them (import -> pip name)."""
OWN = {'zeus_ros', 'sim_bridge'}


def _imports() -> set[str]:
    """Top-level names imported anywhere in the installed code and the launch file."""
    files = [*REPO.glob('zeus_ros/**/*.py'), *REPO.glob('sim_bridge/**/*.py'),
             *REPO.glob('launch/*.py')]
    names: set[str] = set()
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(alias.name.split('.')[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split('.')[0])
    return names - set(sys.stdlib_module_names) - OWN


def test_every_import_has_a_rosdep_key_or_the_documented_pip_step() -> None:
    """ROS packages by name, Python libraries by rosdep key, the rest in README's pip line."""
    from catkin_pkg.package import parse_package

    declared = {dep.name for dep in parse_package(str(REPO / 'package.xml')).exec_depends}
    assert {'launch', 'launch_ros', 'ament_index_python'} <= declared
    readme = (REPO / 'docs' / 'usage.md').read_text()
    [pip_line] = re.findall(r'^python3 -m pip install .*$', readme, flags=re.MULTILINE)
    missing = []
    for name in sorted(_imports()):
        if name in PIP_ONLY:
            if PIP_ONLY[name] not in pip_line:
                missing.append(f'{name} (not in the README pip step)')
        elif IMPORT_TO_DEPENDENCY.get(name, name) not in declared:
            missing.append(f'{name} -> {IMPORT_TO_DEPENDENCY.get(name, name)}')
    assert not missing, f'imported but not declared in package.xml: {missing}'
    requirements = (REPO / 'requirements.txt').read_text()
    for pin in re.findall(r'(\S+==\S+)', pip_line):  # the pip step installs the tested pins
        assert pin in requirements, pin
