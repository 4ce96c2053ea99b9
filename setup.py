"""Install zeus_ros as an ament_python package (colcon build) or a plain Python package."""

from glob import glob
import os

from setuptools import find_packages, setup

PACKAGE = 'zeus_ros'


def tree(source: str, target: str) -> list[tuple[str, list[str]]]:
    """List data_files entries that mirror the directory `source` under share/zeus_ros/target."""
    entries = []
    for root, _dirs, files in os.walk(source):
        paths = [os.path.join(root, name) for name in files if not name.endswith('.pyc')]
        if paths:
            relative = os.path.relpath(root, source)
            entries.append((os.path.normpath(os.path.join('share', PACKAGE, target, relative)),
                            paths))
    return entries


def zoo_files() -> list[tuple[str, list[str]]]:
    """data_files of the model zoo: checkpoints/<family>/ for every family of zoo.yaml."""
    import yaml

    with open(os.path.join('checkpoints', 'zoo.yaml'), encoding='utf-8') as handle:
        families = yaml.safe_load(handle)['families']
    entries = [(os.path.join('share', PACKAGE, 'checkpoints'),
                ['checkpoints/README.md', 'checkpoints/zoo.yaml'])]
    for name in families:
        folder = name.lower().replace('-', '_')
        entries += tree(os.path.join('checkpoints', folder), os.path.join('checkpoints', folder))
    return entries


setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(include=['zeus_ros', 'zeus_ros.*', 'sim_bridge', 'sim_bridge.*']),
    package_data={'sim_bridge': ['assets/**/*']},
    include_package_data=True,
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/launch', glob('launch/*.launch.py')),
        ('share/' + PACKAGE + '/msg', glob('msg_defs/msg/*.msg')),
        *tree('params', 'params'),
        # The model zoo only (checkpoints/README.md): one folder per family in zoo.yaml, the
        # index and the manifest. The research archive beside it stays in the repository.
        *zoo_files(),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='zeus_ros developers',
    maintainer_email='zeus-ros@example.org',
    description='ZeUS zero-shot adaptation to changing physics, as ROS 2 nodes.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'sim_bridge_node = zeus_ros.nodes.sim_bridge_node:main',
            'context_estimator_node = zeus_ros.nodes.context_estimator_node:main',
            'policy_node = zeus_ros.nodes.policy_node:main',
            'recorder_node = zeus_ros.nodes.recorder_node:main',
            'robot_bridge_node = zeus_ros.nodes.robot_bridge_node:main',
            'continual_trainer_node = zeus_ros.nodes.continual_node:main',
            'loop_container = zeus_ros.nodes.container:main',
            'zeus = zeus_ros.cli:main',
        ],
    },
)
