"""The one set of launch defaults: `ros2 launch zeus_ros zeus.launch.py` and `zeus launch`.

Both ask `plan()` which nodes to start with which parameters, so they cannot drift apart. The
params file defaults to the installed share/zeus_ros/params/zeus.yaml, and a relative path in
it (a `checkpoint`) is looked up next to the params file, then in the package share, then in
the working directory: the installed launch runs from any folder. Pure Python (no `launch`
import), so it is unit-tested without a ROS launch installation.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
import os
from pathlib import Path
from typing import Any

import yaml

from zeus_ros.system.respawn import LaunchExits, LaunchRespawn, policies_from_params
from zeus_ros.yaml_text import YamlTextError, load_yaml_text

__all__ = [
    'AGENT_NODES',
    'ARGUMENTS',
    'BACKGROUND',
    'CLOCK_CHOICES',
    'CONTAINER',
    'CONTAINER_EXECUTABLE',
    'CONTAINER_MODULE',
    'CONTAINER_NO_INTRA',
    'LOG_LEVELS',
    'NODES',
    'OBS_CHOICES',
    'PACKAGE',
    'PAIRINGS',
    'TRAINER',
    'LaunchArgument',
    'LaunchPlan',
    'NodePlan',
    'clock_topic',
    'default_params_file',
    'launch_env',
    'launch_exits',
    'launch_respawns',
    'pairing_parameters',
    'param_args',
    'parse_bool',
    'pixel_checkpoint',
    'plan',
    'plan_from_arguments',
    'resolve_path',
    'ros_arg_value',
    'share_dir',
    'start_args',
    'start_parameters',
    'task_overrides',
    'zoo_checkpoint',
]

PACKAGE = 'zeus_ros'
NODES: dict[str, str] = {
    'sim_bridge': 'zeus_ros.nodes.sim_bridge_node',
    'context_estimator': 'zeus_ros.nodes.context_estimator_node',
    'policy': 'zeus_ros.nodes.policy_node',
    'recorder': 'zeus_ros.nodes.recorder_node',
    'robot_bridge': 'zeus_ros.nodes.robot_bridge_node',
    'continual_trainer': 'zeus_ros.nodes.continual_node',
}
"""Node name -> module; the installed executable is `<name>_node` (continual_trainer_node)."""
DEFAULT_NODES = ('sim_bridge', 'context_estimator', 'policy')
STEP_SOURCES = frozenset({'sim_bridge', 'robot_bridge'})
"""Nodes that publish the steps (a launch runs one): they wait for every other node."""
ANSWER_READERS: dict[str, frozenset[str]] = {
    'context_estimator': frozenset({'policy', 'recorder'}),  # zeus/context
    'policy': STEP_SOURCES | {'recorder'},  # zeus/action
}
"""Who in a group subscribes to a node's answer to a step: its `expected_subscribers`."""
RECORDED_ANSWERS: dict[str, str] = {
    **dict.fromkeys(STEP_SOURCES, '/zeus/step'),
    'context_estimator': '/zeus/context',
    'policy': '/zeus/action',
}
"""The lockstep topic each node of a group publishes: the recorder's `expected_publishers`."""
AGENT_NODES = ('context_estimator', 'policy')
"""Nodes that load a checkpoint (the `checkpoint` launch argument sets both: a matched pair)."""
RECORDS_OTHERS = frozenset({'recorder'})
"""Nodes that stop last and whose exit does not end the launch."""
TRAINER = 'continual_trainer'
"""continual: retrains, gates and swaps in the background; its exit does not end the launch."""
BACKGROUND = RECORDS_OTHERS | {TRAINER}
"""Nodes outside the control loop: never in the container, never waited for at step 0."""
CONTINUAL_SPLIT_S = 20.0
"""continual: the recorder's split period unless the params file sets one (a round reads only
closed splits, so this is the delay before new steps can be trained on: 1,000 steps at 50 Hz)."""
CONTINUAL_NOISE = 0.1
"""continual: the policy's exploration noise unless the params file sets a nonzero one. The
critic of a round compares actions, so the recording needs some variety; a deployment with
noise 0 gives it none. The continual results are measured with it, and so pay its cost."""
CONTAINER = 'container'
CONTAINER_MODULE = 'zeus_ros.nodes.container'
CONTAINER_EXECUTABLE = 'loop_container'
"""single_process: every node but the recorder runs in this one process (nodes/container.py)."""
CONTAINER_NO_INTRA = '--no-intra-process'
"""The container's switch: messages between its nodes through DDS (nodes/intra_process.py)."""
PATH_PARAMETERS = {'context_estimator': ('checkpoint',), 'policy': ('checkpoint',)}
"""Parameters holding a file to read: resolved to an absolute path before the node starts."""
LOG_LEVELS = ('debug', 'info', 'warn', 'error', 'fatal')
OBS_CHOICES = ('', 'state', 'pixels')
"""`obs`: '' keeps the params file's sim_bridge `pixels`."""
PIXEL_METHOD = 'pixels_student'
"""The zoo file name of a family's pixel checkpoint (<family>/pixels_student.pt)."""
_TRUE = ('true', '1', 'yes', 'on')
_FALSE = ('false', '0', 'no', 'off', '')


@dataclass(frozen=True)
class LaunchArgument:
    """One launch argument: `name:=value` for ros2 launch, `--name` for zeus launch."""

    name: str
    default: str
    description: str


ARGUMENTS: tuple[LaunchArgument, ...] = (
    LaunchArgument('namespace', '', 'namespace of the whole system (zeus/* topics move with it; '
                   '/diagnostics stays global, /clock too unless on simulation time: clock)'),
    LaunchArgument('use_sim_time', 'false', 'every node runs on the simulation clock, which '
                   'sim_bridge publishes (/clock; namespaced: <namespace>/clock, see clock)'),
    LaunchArgument('clock', '', 'where the simulation clock goes: global (/clock), '
                   'namespace (<namespace>/clock: several simulated systems in one domain, '
                   'each on its own time) or an absolute topic; every node is remapped '
                   '(empty: namespace for a namespaced system on simulation time, else '
                   'global)'),
    LaunchArgument('params_file', '', 'ROS 2 params file for all nodes (empty: the installed '
                   'share/zeus_ros/params/zeus.yaml)'),
    LaunchArgument('task', '', "task family to run (empty: the params file's): sim_bridge runs "
                   'its demo schedule and the agent nodes its zoo checkpoint '
                   '(params/tasks/<task>.yaml)'),
    LaunchArgument('checkpoint', '', 'checkpoint for context_estimator AND policy (empty: '
                   "the one in the params file, or the task's zoo checkpoint)"),
    LaunchArgument('obs', '', 'what the agent sees: pixels (sim_bridge renders 84x84 frames '
                   "and, without a checkpoint, the task's zoo pixel checkpoint acts: "
                   "experimental; with robot: the robot's camera, image_topic) or state (empty: "
                   "the params file's)"),
    LaunchArgument('record', 'false', 'also start the recorder (sim_bridge waits for it too)'),
    LaunchArgument('continual', 'false', 'record, and retrain from the closed splits in the '
                   'background (continual_trainer, niced, 1 torch thread): gate each candidate '
                   'against the deployed checkpoint, swap it in live, roll back a live '
                   'regression'),
    LaunchArgument('log_level', 'info', 'log level of every node: ' + ', '.join(LOG_LEVELS)),
    LaunchArgument('robot', 'false', "robot_bridge in sim_bridge's place (params_file: the "
                   "robot's, e.g. params/robot_bridge.yaml)"),
    LaunchArgument('single_process', 'false', 'run the nodes of the control loop as nodes of '
                   'one process on one executor (the recorder stays separate)'),
    LaunchArgument('intra_process', 'true', 'single_process: its nodes hand each other '
                   'messages as Python objects (false: through DDS, as between processes)'),
    LaunchArgument('lock_parameters', 'false', 'deployment: the bridges, estimator and policy '
                   'declare their safety-relevant parameters read-only (lock_parameters:=true), '
                   'so no process can change them live; the checkpoint stays live '
                   '(docs/security.md)'),
)
LOCKABLE = ('sim_bridge', 'robot_bridge', 'context_estimator', 'policy')
"""The nodes with a `lock_parameters` parameter (params.LOCK_SPECS)."""


@dataclass(frozen=True)
class NodePlan:
    """One node to start: its overrides go after the params file, so they win."""

    name: str
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def executable(self) -> str:
        """The console script colcon installs (lib/zeus_ros/<name>_node)."""
        return f'{self.name}_node'

    @property
    def module(self) -> str:
        """The module `python -m` runs."""
        return NODES[self.name]

    @property
    def records_others(self) -> bool:
        """Stops last; its exit does not stop the others."""
        return self.name in RECORDS_OTHERS

    @property
    def background(self) -> bool:
        """Outside the control loop: its exit does not stop the others."""
        return self.name in BACKGROUND


@dataclass(frozen=True)
class LaunchPlan:
    """Everything both launchers need: namespace, params file, log level and the nodes."""

    namespace: str
    params_file: Path
    log_level: str
    nodes: tuple[NodePlan, ...]
    single_process: bool = False
    intra_process: bool = True
    clock: str = ''
    """The clock topic every node is remapped to ('': /clock)."""

    def parameter(self, name: str, key: str) -> Any:
        """Node `name`'s `key` as it will start: the plan's override, else the params file's."""
        for node in self.nodes:
            if node.name == name and key in node.parameters:
                return node.parameters[key]
        values = [s[key] for s in _node_sections(read_params(self.params_file), name)
                  if s.get(key) not in (None, '')]
        return values[-1] if values else None

    @property
    def remappings(self) -> list[tuple[str, str]]:
        """(from, to) remaps of every node: the clock, when it is not /clock."""
        return [('/clock', self.clock)] if self.clock else []

    @property
    def contained(self) -> tuple[NodePlan, ...]:
        """The nodes that share the container process (none unless single_process)."""
        if not self.single_process:
            return ()
        return tuple(node for node in self.nodes if not node.background)

    @property
    def separate(self) -> tuple[NodePlan, ...]:
        """The nodes that run as processes of their own."""
        return tuple(node for node in self.nodes if node not in self.contained)

    def container_args(self) -> list[str]:
        """Arguments of the container: each contained node with its own `--ros-args`."""
        args = [] if self.intra_process else [CONTAINER_NO_INTRA]
        args += ['--ros-args', '--log-level', self.log_level]
        for node in self.contained:
            args += ['--node', node.name, '--ros-args', *self.ros_args(node)]
        return args

    def ros_args(self, node: NodePlan) -> list[str]:
        """`--ros-args` arguments of one node as `zeus launch` passes them on its command line."""
        args = ['--params-file', str(self.params_file)]
        if self.namespace:
            args += ['-r', f'__ns:={self.namespace}']
        for source, target in self.remappings:
            args += ['-r', f'{source}:={target}']
        return [*args, *param_args(node.parameters), '--log-level', self.log_level]


CLOCK_CHOICES = ('global', 'namespace')


def clock_topic(clock: str, namespace: str, sim_time: bool = False) -> str:
    """The clock topic `clock` names in `namespace` ('' for /clock); ValueError says why not.

    global: /clock, ROS's one clock; namespace: <namespace>/clock, so two simulated systems in
    one domain each run on their own time (a second publisher on a clock is an ERROR on
    /diagnostics); an absolute topic: that topic. Unset (''): namespace for a namespaced system
    on simulation time (`sim_time`), else global. Why: on the shared /clock a second simulated
    system stalls it and mixes both clocks in its bag, and forgetting an option must not.
    """
    value = clock.strip()
    if not value:
        value = 'namespace' if namespace and sim_time else 'global'
    if value in ('global', '/clock'):
        return ''
    if value == 'namespace':
        if not namespace:
            raise ValueError('clock:=namespace (--clock namespace) needs a namespace '
                             '(namespace:=r1 / --namespace r1)')
        return f'{namespace}/clock'
    parts = value.split('/')
    if not value.startswith('/') or not all(
            part and (part[0].isalpha() or part[0] == '_')
            and all(c.isalnum() or c == '_' for c in part) for part in parts[1:]):
        raise ValueError(f'clock {value!r}: choose {" or ".join(CLOCK_CHOICES)}, or an '
                         'absolute topic name such as /r1/clock')
    return value


def param_args(values: Mapping[str, Any]) -> list[str]:
    """Parameter values as `--ros-args` arguments: `-p key:=value` each."""
    return [arg for key, value in values.items()
            for arg in ('-p', f'{key}:={ros_arg_value(value)}')]


def ros_arg_value(value: Any) -> str:
    """A parameter value as `-p key:=value` parses it back (YAML; lists in flow style)."""
    if isinstance(value, list | tuple):
        return '[' + ','.join(ros_arg_value(item) for item in value) + ']'
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return yaml.safe_dump(value, default_style="'").strip().removesuffix('\n...')
    return str(value)


def share_dir() -> Path:
    """share/zeus_ros of the installed package; the repository when it is not installed."""
    try:
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )
    except ImportError:
        return Path(__file__).resolve().parents[2]
    try:
        return Path(get_package_share_directory(PACKAGE))
    except PackageNotFoundError:
        return Path(__file__).resolve().parents[2]


def task_overrides(task: str, checkpoint: str = '') -> dict[str, Any]:
    """Per node, the parameters that make the group run `task` (ValueError when unknown).

    sim_bridge gets the family's demo schedule (switch every N steps through its values);
    estimator and policy the task name; 'checkpoint' the family's zoo checkpoint unless one is
    given.
    """
    from sim_bridge.families import family

    try:
        every, values = family(task).demo_schedule()
    except ValueError as error:
        raise ValueError(f'task {task!r}: {error}') from None
    bridge = {'task': task, 'schedule.kind': 'switch', 'schedule.every': every,
              'schedule.values': values}
    overrides: dict[str, Any] = {'sim_bridge': bridge, 'robot_bridge': {},
                                 **{node: {'task': task} for node in AGENT_NODES}}
    if not checkpoint:
        overrides['checkpoint'] = str(zoo_checkpoint(task))
    return overrides


def pixel_checkpoint(task: str) -> Path:
    """The family's zoo pixel checkpoint (ValueError naming the families that have one)."""
    try:
        return zoo_checkpoint(task, PIXEL_METHOD)
    except ValueError:
        from sim_bridge.registry import TASK_NAMES

        have = []
        for name in TASK_NAMES:
            try:
                zoo_checkpoint(name, PIXEL_METHOD)
            except ValueError:
                continue
            have.append(name)
        raise ValueError(f'{task} has no pixel checkpoint in the zoo (families with one: '
                         f'{", ".join(have) or "none"}); pass a pixel checkpoint you trained '
                         '(zeus distill)') from None


def _params_task(params: Mapping[str, Any], path: Path, bridge: str = 'sim_bridge') -> str:
    """The bridge's task in the params file (what runs, or the robot is, when none is given)."""
    tasks = [s['task'] for s in _node_sections(params, bridge) if s.get('task')]
    if not tasks:
        raise ValueError(f'{path} names no {bridge} task: pass task:= / --task')
    return str(tasks[-1])


def _robot_pixel_checkpoint(params: Mapping[str, Any], path: Path, checkpoint: str) -> str:
    """Pixels on a robot: its camera must be set; without `checkpoint`, its task's zoo one.

    robot_bridge republishes the camera per step (`image_topic`); sim_bridge's `pixels` does
    not apply, so a robot without a camera would leave a pixel policy waiting for frames.
    """
    if not any(s.get('image_topic') for s in _node_sections(params, 'robot_bridge')):
        raise ValueError(f'obs pixels with robot: {path} sets no robot_bridge image_topic '
                         '(the camera the pixel agents see)')
    return checkpoint or str(pixel_checkpoint(_params_task(params, path, 'robot_bridge')))


def zoo_checkpoint(task: str, method: str = 'zeus') -> Path:
    """The family's zoo checkpoint (`<family>/<method>.pt`): this checkout's, else the share's.

    A user's family file may name its own: relative to the file's folder (or absolute).
    ValueError naming the families that have one when `task` has none.
    """
    from sim_bridge.families import builtin_family_file, family

    declared_family = family(task)
    declared = declared_family.checkpoint
    if declared is None:
        from sim_bridge.registry import TASK_NAMES

        zoo = [name for name in TASK_NAMES if family(name).checkpoint]
        raise ValueError(f'{task} has no zoo checkpoint (families with one: {", ".join(zoo)}); '
                         'pass a checkpoint you trained')
    relative = Path(declared).with_name(f'{method}.pt') if method != 'zeus' else Path(declared)
    candidates = [Path(__file__).resolve().parents[2] / 'checkpoints' / relative,
                  share_dir() / 'checkpoints' / relative]
    if declared_family.source.resolve() != builtin_family_file(declared_family.name).resolve():
        candidates.insert(0, declared_family.source.parent / relative)
    found = next((path for path in candidates if path.is_file()), None)
    if found is None:
        raise ValueError(f'{task}: zoo checkpoint {relative} not found; looked in '
                         + ', '.join(str(c.parent) for c in candidates))
    return found


def default_params_file() -> Path:
    """The installed params file every launch uses unless given another."""
    return share_dir() / 'params' / 'zeus.yaml'


def parse_bool(name: str, text: str | bool) -> bool:
    """A launch argument's true/false (as `ros2 launch` spells it); ValueError names it."""
    if isinstance(text, bool):
        return text
    value = text.strip().lower()
    if value in _TRUE:
        return True
    if value in _FALSE:
        return False
    raise ValueError(f'launch argument {name}:={text!r} must be true or false')


def resolve_path(value: str, params_dir: Path | None, what: str = 'file') -> Path:
    """An existing file: absolute as given, else next to the params file, in the share, in cwd.

    Raises ValueError naming every place looked in, so a typo is found before any node starts.
    """
    path = Path(os.path.expanduser(value))
    if path.is_absolute():
        return path
    bases = [*([params_dir] if params_dir is not None else []), share_dir(), Path.cwd()]
    candidates = [Path(os.path.abspath(base / path)) for base in bases]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise ValueError(f'{what} {value!r} not found; looked in: '
                     + ', '.join(str(c) for c in candidates))


def _node_sections(params: Mapping[str, Any], name: str) -> list[Mapping[str, Any]]:
    """The ros__parameters that apply to node `name` (`name`, `/**/name`, `/ns/name`, `/**`)."""
    sections = []
    for key, section in params.items():
        last = str(key).rstrip('/').rsplit('/', 1)[-1]
        if (last == name or key in ('/**', '**')) and isinstance(section, Mapping):
            sections.append(section.get('ros__parameters') or {})
    return sections


def read_params(params_file: Path) -> dict[str, Any]:
    """The params file as a mapping; ValueError (one line) when it is not a ROS params file.

    Checked here what rcl's parser would refuse in every node with a traceback each: text that
    is not UTF-8 YAML, an empty file, sections without ros__parameters, values that are not a
    bool, number, string or non-empty list of one of these.
    """
    if not params_file.is_file():
        raise ValueError(f'params file {params_file} does not exist')
    where = f'params file {params_file}'
    try:
        data = load_yaml_text(params_file)
    except YamlTextError as error:
        raise ValueError(f'{where}: {error}') from None
    if data is None:
        raise ValueError(f'{where}: the file is empty; expected node_name: ros__parameters: ...')
    if not isinstance(data, dict):
        raise ValueError(f'{where}: expected node_name: ros__parameters: ...')
    for node, section in data.items():
        if not isinstance(section, dict) or 'ros__parameters' not in section \
                or not isinstance(section['ros__parameters'], dict | None):
            raise ValueError(f'{where}: {node}: expected a ros__parameters: mapping under it')
        _check_values(section['ros__parameters'] or {}, f'{where}: {node}')
    return data


def _check_values(params: Mapping[str, Any], where: str, prefix: str = '') -> None:
    """Every parameter value is one rcl can read: a scalar or a non-empty list of one type."""
    for key, value in params.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            _check_values(value, where, f'{name}.')
        elif isinstance(value, list):
            kinds = {type(item) for item in value}
            if not value or len(kinds) > 1 or not kinds <= {bool, int, float, str}:
                raise ValueError(f'{where}: parameter {name}: {value!r} is not a non-empty list '
                                 'of bools, integers, floats or strings (one type)')
        elif not isinstance(value, bool | int | float | str):
            raise ValueError(f'{where}: parameter {name}: {value!r} is not a bool, number, '
                             'string or list')


def start_parameters(name: str, group: Sequence[str]) -> dict[str, int | list[str]]:
    """What node `name` waits for before step 0 in `group` (its parameters).

    The step source waits for every other node of the group on zeus/step, by name
    (`observers`; `min_observers` their number): a count alone could be met by a launcher's
    own step subscriber (zeus launch's status line, the demo's inspector) or a user's
    `ros2 topic echo` while a node of the group is still starting. The estimator and the
    policy subscribe to the steps only once their answer (context, action) is matched by its
    readers in the group (`expected_subscribers`), and a recorder only once its readers
    matched the group's publishers of the steps and answers (`expected_publishers`), so the
    step source waits for them too and a recorder's bag holds every topic from step 0.
    """
    if name in STEP_SOURCES:
        others = [other for other in group if other != name]
        return {'min_observers': len(others), 'observers': others or ['']}
    if name in ANSWER_READERS:
        readers = sum(1 for other in group if other in ANSWER_READERS[name])
        return {'expected_subscribers': readers} if readers else {}
    if name in RECORDS_OTHERS:
        topics = [topic for node, topic in RECORDED_ANSWERS.items() if node in group]
        return {'expected_publishers': topics} if topics else {}
    return {}


PAIRINGS: dict[str, dict[str, tuple[str, ...]]] = {
    'sim_bridge': {'action_sender': ('policy',)},
    'robot_bridge': {'action_sender': ('policy',)},
    'context_estimator': {'step_source': tuple(sorted(STEP_SOURCES))},
    'policy': {'step_source': tuple(sorted(STEP_SOURCES)),
               'context_source': ('context_estimator',)},
}
"""Per node, the parameter naming each peer it pairs with, and who in a group that peer is."""


def pairing_parameters(name: str, group: Sequence[str], namespace: str = '') -> dict[str, str]:
    """The fully qualified peers node `name` pairs with in `group` (senders.py), by parameter.

    Named by the launch rather than found at start: a stray publisher that happens to be the
    only one when a node starts can then never be paired with.
    """
    found = {}
    for key, peers in PAIRINGS.get(name, {}).items():
        peer = next((other for other in group if other in peers), None)
        if peer is not None:
            found[key] = f'{namespace}/{peer}'
    return found


def launch_env() -> dict[str, str]:
    """What a launch adds to its nodes' environment: one pairing key for the whole group.

    With it a node re-pairs with a restarted peer only when the peer's start hello proves the
    key (nodes/handshake.py); a key already in the environment is kept (several launches
    that must pair with each other share it).
    """
    from zeus_ros.nodes.handshake import KEY_ENV, new_key

    return {KEY_ENV: os.environ.get(KEY_ENV) or new_key()}


def launch_respawns(plan: LaunchPlan) -> dict[str, LaunchRespawn]:
    """launch_ros's respawn arguments per process of `ros2 launch` (nodes, the container).

    From the params file's `/**/zeus_launch` respawn: section, as `zeus launch` reads it
    (system/respawn.py). Not restarted there: the trainer (`zeus launch` does not either) and
    a recorder with a set `output` (launch_ros restarts it with the same one, which it then
    refuses as not empty: `zeus launch` gives the restart a new folder).
    """
    params = read_params(plan.params_file)
    policies = policies_from_params(params, [*NODES, CONTAINER])
    names = [CONTAINER] if plan.contained else []
    names += [node.name for node in plan.separate]
    respawns = {name: LaunchRespawn.from_policy(policies[name]) if name in policies
                else LaunchRespawn() for name in names}
    respawns[TRAINER] = LaunchRespawn()
    recorder = next((node for node in plan.separate if node.name in RECORDS_OTHERS), None)
    if recorder is not None and (recorder.parameters.get('output') or any(
            s.get('output') for s in _node_sections(params, recorder.name))):
        respawns[recorder.name] = LaunchRespawn()
    return {name: respawns[name] for name in names}


def launch_exits(plan: LaunchPlan) -> dict[str, LaunchExits]:
    """Per process of `ros2 launch`, the exit bookkeeping its OnProcessExit handler uses."""
    return {name: LaunchExits(name, respawn, background=name in BACKGROUND)
            for name, respawn in launch_respawns(plan).items()}


def start_args(name: str, group: Sequence[str]) -> list[str]:
    """start_parameters as `-p` arguments: for nodes started one by one (the demo, tests)."""
    return param_args(start_parameters(name, group))


def plan(
    *,
    namespace: str = '',
    use_sim_time: bool = False,
    params_file: Path | str | None = None,
    checkpoint: str = '',
    task: str = '',
    record: bool = False,
    log_level: str = 'info',
    nodes: Sequence[str] = DEFAULT_NODES,
    robot: bool = False,
    single_process: bool = False,
    intra_process: bool = True,
    continual: bool = False,
    clock: str = '',
    obs: str = '',
    lock_parameters: bool = False,
) -> LaunchPlan:
    """Which nodes to start with which parameter overrides (ValueError on a bad argument).

    sim_bridge waits for every other node of the group (the recorder included) on zeus/step,
    and estimator and policy for the readers of their answers (`start_parameters`), so none of
    them misses step 0; a relative checkpoint becomes an absolute path. With
    `robot`, robot_bridge takes sim_bridge's place; without any checkpoint the robot's first
    recording is made by the random policy alone (no estimator), which reads the robot's shape
    from the params file. `single_process` changes only how the nodes are hosted (one process,
    see LaunchPlan.container_args), never their parameters; `intra_process` (single_process
    only) whether the container's nodes hand each other messages in process. `task` runs
    another family than the params file's: its demo schedule on sim_bridge, its zoo checkpoint
    on the agent nodes (unless `checkpoint` is given). `continual` records and adds the
    continual trainer, pointed at the recorder's output and the agents' checkpoint. `clock`
    moves the simulation clock of every node (`clock_topic`; unset, a namespaced system on
    simulation time, by `use_sim_time` or its params file, gets <namespace>/clock). Each node
    is told whom it pairs with (`pairing_parameters`) unless the params file names one. `obs`
    'pixels' turns on sim_bridge's frames and, without `checkpoint`, deploys the family's zoo
    pixel checkpoint (with `robot`: the robot's camera, `image_topic`, must be set; the robot
    task's checkpoint).
    `lock_parameters` makes the safety-relevant parameters of the LOCKABLE nodes read-only.
    """
    if not intra_process and not single_process:
        raise ValueError('intra_process:=false (--no-intra-process) applies to single_process '
                         'only: add single_process:=true (--single-process) or drop it')
    names = list(dict.fromkeys(nodes))
    if robot:  # a robot steps the loop: robot_bridge takes sim_bridge's place
        names = [('robot_bridge' if name == 'sim_bridge' else name) for name in names]
    if (record or continual) and 'recorder' not in names:
        names.append('recorder')
    if continual and TRAINER not in names:
        names.append(TRAINER)
    unknown = [name for name in names if name not in NODES]
    if unknown:
        raise ValueError(f'unknown node(s) {unknown}; choose from {list(NODES)}')
    if log_level.lower() not in LOG_LEVELS:
        raise ValueError(f'log_level {log_level!r}: choose one of {", ".join(LOG_LEVELS)}')
    given = str(params_file) if params_file not in (None, '') else ''
    path = Path(os.path.abspath(os.path.expanduser(given))) if given else default_params_file()
    params = read_params(path)
    if obs not in OBS_CHOICES:
        raise ValueError(f'obs {obs!r}: choose one of {", ".join(o for o in OBS_CHOICES if o)}')
    if obs == 'pixels' and robot:
        checkpoint = _robot_pixel_checkpoint(params, path, checkpoint)
    elif obs == 'pixels' and not checkpoint:
        checkpoint = str(pixel_checkpoint(task or _params_task(params, path)))
    random_robot = robot and not checkpoint and not any(
        section.get('checkpoint') for node in AGENT_NODES
        for section in _node_sections(params, node))
    if random_robot:
        names = [name for name in names if name != 'context_estimator']
    family_overrides = task_overrides(task, checkpoint) if task else {}
    if obs and not robot:
        family_overrides.setdefault('sim_bridge', {})['pixels'] = obs == 'pixels'
    if task and not checkpoint:
        checkpoint = str(family_overrides.pop('checkpoint'))
    ns = namespace.strip().strip('/')
    sim_time = use_sim_time or any(section.get('use_sim_time') is True for name in names
                                   for section in _node_sections(params, name))
    clock_to = clock_topic(clock, f'/{ns}' if ns else '', sim_time)
    planned = []
    loop = [name for name in names if name != TRAINER]
    for name in names:
        overrides: dict[str, Any] = {}
        overrides.update(start_parameters(name, loop))
        overrides.update({key: value for key, value in
                          pairing_parameters(name, loop, f'/{ns}' if ns else '').items()
                          if not any(s.get(key) for s in _node_sections(params, name))})
        for key in PATH_PARAMETERS.get(name, ()):
            if key == 'checkpoint' and checkpoint:
                overrides[key] = str(resolve_path(checkpoint, None, 'checkpoint'))
                continue
            values = [s[key] for s in _node_sections(params, name) if s.get(key)]
            if values:
                overrides[key] = str(resolve_path(str(values[-1]), path.parent,
                                                  f'{name} {key} (params file {path})'))
        overrides.update(family_overrides.get(name, {}))
        if name == 'recorder' and _frames_best_effort(params, robot) and not any(
                'image_best_effort' in s for s in _node_sections(params, name)):
            overrides['image_best_effort'] = True
        if random_robot and name == 'policy':
            overrides['task'] = str(path)  # the robot's params file declares its task
        if use_sim_time:
            overrides['use_sim_time'] = True
        if lock_parameters and name in LOCKABLE:
            overrides['lock_parameters'] = True
        planned.append(NodePlan(name, overrides))
    planned = _label_recordings(planned, params, path, task, TRAINER in names)
    if TRAINER in names:
        planned = _continual_plan(planned, params, task)
    return LaunchPlan(namespace=f'/{ns}' if ns else '', params_file=path,
                      log_level=log_level.lower(), nodes=tuple(planned),
                      single_process=single_process, intra_process=intra_process,
                      clock=clock_to)


def _label_recordings(planned: list[NodePlan], params: Mapping[str, Any], path: Path,
                      task: str, continual: bool) -> list[NodePlan]:
    """Tell the recorder what its bags are: kind, task, the checkpoint deployed at the start.

    What `zeus bags` lists and `zeus train --bags` chooses by (bags/kinds.py); a params file's
    own values win.
    """
    checkpoint = next((str(node.parameters['checkpoint']) for node in planned
                       if node.name == 'policy' and node.parameters.get('checkpoint')), '')
    if not checkpoint:
        checkpoint = next((str(s['checkpoint']) for s in _node_sections(params, 'policy')
                           if s.get('checkpoint')), '')
    source = 'robot_bridge' if any(node.name == 'robot_bridge' for node in planned) \
        else 'sim_bridge'
    if not task:
        try:
            task = _params_task(params, path, source)
        except ValueError:
            task = ''
    if task:
        from sim_bridge.registry import declared_task

        declared = declared_task(task)
        task = declared.name if declared is not None else task
    label = {'kind': 'continual' if continual else 'manual', 'label_task': task,
             'label_checkpoint': checkpoint}
    sections = _node_sections(params, 'recorder')
    return [NodePlan(node.name, {**node.parameters, **{
        key: value for key, value in label.items() if not any(key in s for s in sections)}})
        if node.name == 'recorder' else node for node in planned]


def _frames_best_effort(params: Mapping[str, Any], robot: bool) -> bool:
    """Whether the step source publishes frames best effort (realtime: topics.image_qos).

    A reliable subscription never matches a best-effort publisher, so a recorder left at its
    default would record no frame at all; robot_bridge always runs in realtime.
    """
    if robot:
        return True
    modes = [s['mode'] for s in _node_sections(params, 'sim_bridge') if 'mode' in s]
    return bool(modes) and modes[-1] == 'realtime'


def _continual_plan(planned: list[NodePlan], params: Mapping[str, Any], task: str
                    ) -> list[NodePlan]:
    """Point the recorder at a known folder with splits and the trainer at it and the agents.

    The recorder's `output` and `split_duration_s` from the params file win; otherwise a new
    bags/continual_<date> folder split every CONTINUAL_SPLIT_S seconds. The policy explores
    with CONTINUAL_NOISE unless its parameters set a nonzero noise.
    """
    import time

    from zeus_ros.bags.kinds import CONTINUAL_PREFIX

    agents = {node.name: node for node in planned if node.name in AGENT_NODES}
    checkpoint = agents.get('policy', NodePlan('policy')).parameters.get('checkpoint')
    if len(agents) < 2 or not checkpoint:
        raise ValueError('continual needs context_estimator and policy with a checkpoint (the '
                         'trainer continues from it): pass --checkpoint / checkpoint:=, --task, '
                         'or set one in the params file')
    recorder = _node_sections(params, 'recorder')
    output = next((s['output'] for s in reversed(recorder) if s.get('output')), '') or \
        f'bags/{CONTINUAL_PREFIX}{time.strftime("%Y%m%d_%H%M%S")}'
    split = next((s['split_duration_s'] for s in reversed(recorder)
                  if s.get('split_duration_s')), CONTINUAL_SPLIT_S)
    output = os.path.abspath(os.path.expanduser(str(output)))
    noise = next((s['noise'] for s in reversed(_node_sections(params, 'policy'))
                  if s.get('noise')), agents['policy'].parameters.get('noise'))
    result = []
    for node in planned:
        extra: dict[str, Any] = {}
        if node.name == 'recorder':
            extra = {'output': output, 'split_duration_s': float(split)}
        elif node.name == TRAINER:
            extra = {'recording': output, 'checkpoint': checkpoint,
                     **({'task': task} if task else {})}
        elif node.name == 'policy' and not noise:
            extra = {'noise': CONTINUAL_NOISE}
        result.append(NodePlan(node.name, {**node.parameters, **extra}))
    return result


def plan_from_arguments(values: Mapping[str, str]) -> LaunchPlan:
    """`plan()` from launch-argument strings (what `ros2 launch` hands the launch file)."""
    known = {argument.name for argument in ARGUMENTS}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f'unknown launch argument(s) {unknown}; known: {sorted(known)}')
    get = {argument.name: values.get(argument.name, argument.default) for argument in ARGUMENTS}
    return plan(namespace=get['namespace'], use_sim_time=parse_bool('use_sim_time',
                                                                    get['use_sim_time']),
                params_file=get['params_file'], checkpoint=get['checkpoint'], task=get['task'],
                record=parse_bool('record', get['record']), log_level=get['log_level'],
                robot=parse_bool('robot', get['robot']),
                single_process=parse_bool('single_process', get['single_process']),
                intra_process=parse_bool('intra_process', get['intra_process']),
                continual=parse_bool('continual', get['continual']), clock=get['clock'],
                obs=get['obs'],
                lock_parameters=parse_bool('lock_parameters', get['lock_parameters']))
