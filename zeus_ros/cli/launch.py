"""`zeus launch`: start the zeus_ros nodes without the ROS launch system, supervise, stop.

Every child gets loopback-only discovery and one shared domain id, its output is streamed with
a `[name]` prefix, and the whole group stops on Ctrl-C or as soon as one node of the control
loop exits for good: a non-zero exit names the node that died. A dead context estimator, policy
or recorder is restarted (by default up to 3 times per 60 s, after a 1 s back-off that doubles;
per node from the params file's `/**/zeus_launch` section or --respawn, zeus_ros/system/respawn.py)
while the bridge applies its safe action; logging never stops control: the recorder restarts
into a new bag, a recorder that cannot write retries on its own, and every gap is reported.
Exit status: 0 clean, 1 a node died for good or failed to stop, 3 the loop ran but degraded (a
node was restarted or the recording has gaps; an unfinished bag is named, `zeus recover`
closes it). Nodes, parameters
and defaults come from `zeus_ros.system.launch_defaults`, exactly as for `ros2 launch zeus_ros
zeus.launch.py`: without --params the installed share/zeus_ros/params/zeus.yaml applies, from
any folder.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
import re
import signal
import subprocess
import sys
import threading
import time
from typing import IO

from zeus_ros.cli_args import ZeusArgumentParser, at_least
from zeus_ros.system import launch_defaults
from zeus_ros.system.launch_defaults import (
    AGENT_NODES,
    CONTAINER,
    CONTAINER_MODULE,
    NODES,
    RECORDS_OTHERS,
    TRAINER,
    LaunchPlan,
)
from zeus_ros.system.processes import ros_env, start_node, stop_nodes
from zeus_ros.system.respawn import (
    BAD_PARAMETERS,
    DEFAULT_POLICIES,
    RespawnPolicy,
    RespawnState,
    parse_cli,
    policies_from_params,
)

RECORDING_GAPS = 3
"""Exit status of a run whose control loop ran to its end degraded: a node was restarted or the
recording has gaps."""
_RECORDING_TO = re.compile(r'recording \d+ topics to (.+) \((?:mcap|sqlite3)\)')
_NOT_RECORDED = re.compile(r'not recorded: (\d+ steps \(.*?\)) \(')
"""The recorder's closing line for steps it could not write (disk full, permission)."""

RECORDER_DRAIN_S = 0.5
"""Pause between the producers' exit and the recorder's signal: DDS may still be delivering
the last steps the producers published, and a bag must hold every one of them."""


@dataclass
class NodeProcess:
    """One supervised child process."""

    name: str
    argv: list[str]
    process: subprocess.Popen[bytes] | None = None
    reader: threading.Thread | None = None
    lines: list[str] = field(default_factory=list)
    restart_at: float | None = None
    """Monotonic time of a restart waiting out its back-off (None: none pending)."""


def node_argv(name: str, params_file: Path | None, extra: Sequence[str] = ()) -> list[str]:
    """Build the argv of one node: `python -m <module> --ros-args --params-file F ...`."""
    argv = [sys.executable, '-m', NODES[name], '--ros-args']
    if params_file is not None:
        argv += ['--params-file', str(params_file)]
    return [*argv, *extra]


def plan_processes(launch: LaunchPlan) -> list[NodeProcess]:
    """One child per planned node: `python -m <module> --ros-args <the plan's arguments>`.

    With single_process, the nodes of the control loop share one child, the container.
    """
    children = [NodeProcess(node.name, [sys.executable, '-m', node.module, '--ros-args',
                                        *launch.ros_args(node)]) for node in launch.separate]
    if launch.contained:  # first: sim_bridge in it waits for every other node
        children.insert(0, NodeProcess(CONTAINER, [sys.executable, '-m', CONTAINER_MODULE,
                                                   *launch.container_args()]))
    return children


def _pump(node: NodeProcess, stream: IO[bytes], out: IO[str], keep: int = 200) -> None:
    """Copy a child's output line by line with its name as prefix; keep the tail for errors."""
    for raw in iter(stream.readline, b''):
        line = raw.decode(errors='replace').rstrip('\n')
        node.lines.append(line)
        del node.lines[:-keep]
        print(f'[{node.name}] {line}', file=out, flush=True)


class Supervisor:
    """Starts a group of nodes and stops all of them together."""

    def __init__(self, nodes: list[NodeProcess], env: dict[str, str],
                 out: IO[str] = sys.stdout,
                 policies: dict[str, RespawnPolicy] | None = None) -> None:
        self.nodes = nodes
        self.env = env
        self.out = out
        self.started = time.monotonic()
        self.gaps: list[str] = []  # one line per recorder death: when, why, which bag
        self.restarts: list[str] = []  # one line per restart of a node of the loop
        self._restarted: set[str] = set()  # recorders restarted at least once
        self.respawns = {name: RespawnState(policy) for name, policy in
                         (DEFAULT_POLICIES if policies is None else policies).items()}

    def start(self) -> None:
        """Start every node in order (sim_bridge first: it waits for its peers)."""
        for node in self.nodes:
            self._start(node)

    def _start(self, node: NodeProcess) -> None:
        node.process = start_node(node.argv, self.env, stdout=subprocess.PIPE)
        assert node.process.stdout is not None
        node.reader = threading.Thread(
            target=_pump, args=(node, node.process.stdout, self.out), daemon=True)
        node.reader.start()

    def wait(self, timeout: float | None = None) -> tuple[str | None, int]:
        """Block until a node of the control loop exits (or timeout); return name and code.

        A recorder that exits meanwhile is restarted (see `_respawn`), not returned.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            for node in list(self.nodes):  # _respawn may drop a node
                assert node.process is not None
                if node.restart_at is not None:  # dead, its back-off running
                    if time.monotonic() >= node.restart_at:
                        node.restart_at = None
                        self._start(node)
                    continue
                code = node.process.poll()
                if code is None:
                    continue
                if node.name == TRAINER:  # retraining stops; the deployed checkpoint runs on
                    print(f'[zeus launch] {node.name} exited with code {code}; the control loop '
                          'keeps running on the checkpoint deployed last', file=sys.stderr,
                          flush=True)
                    self.nodes.remove(node)
                    continue
                others = [n for n in self.nodes if n is not node and n.name not in
                          RECORDS_OTHERS and n.process is not None and n.process.poll() is None]
                # Exit 2 is a refused configuration, not a crash: a restart would refuse it too.
                if node.name in RECORDS_OTHERS and others and code != BAD_PARAMETERS:
                    self._respawn(node, code)
                    continue
                if node.name in RECORDS_OTHERS and others and node.name in self._restarted:
                    # A restarted recorder that refuses to start (its new output) must not
                    # stop the loop either: the rest of the run goes unrecorded, named.
                    self._give_up_recorder(node, code)
                    continue
                if code not in (0, BAD_PARAMETERS) and self._restart_loop_node(node, code):
                    continue
                return node.name, code
            if deadline is not None and time.monotonic() > deadline:
                return None, 0
            time.sleep(0.1)

    def _delay(self, node: NodeProcess) -> float | None:
        """Seconds before restarting `node` (its policy's back-off); None: not again."""
        state = self.respawns.get(node.name)
        return None if state is None else state.next_delay(time.monotonic())

    def _restart_loop_node(self, node: NodeProcess, code: int) -> bool:
        """A node of the loop crashed: restart it after its back-off if its policy allows.

        Meanwhile the bridge applies its safe action (no action within its action_timeout).
        """
        delay = self._delay(node)
        when = time.monotonic() - self.started
        if delay is None:
            state = self.respawns.get(node.name)
            if state is not None and state.policy.limit:
                print(f'[zeus launch] {node.name} died with exit code {code}, more than '
                      f'{state.policy.text()}: not restarting it again', file=sys.stderr,
                      flush=True)
            return False
        if node.reader is not None:
            node.reader.join(timeout=2)
        state = self.respawns[node.name]
        self.restarts.append(f'{node.name} died at {when:.1f} s (exit code {code}), restarted')
        print(f'[zeus launch] {node.name} died with exit code {code}; the loop keeps running '
              f'on the safe action; restarting it in {delay:g} s (restart {len(state.deaths)}; '
              f'{state.policy.text()})', file=sys.stderr, flush=True)
        node.lines = []
        node.restart_at = time.monotonic() + delay
        return True

    def _respawn(self, node: NodeProcess, code: int) -> None:
        """Logging must not stop control: report the dead recorder, restart it into a new bag."""
        if node.reader is not None:
            node.reader.join(timeout=2)
        bags = [m.group(1) for m in map(_RECORDING_TO.search, node.lines) if m]
        when = time.monotonic() - self.started
        if not bags:
            bag = 'it had not started a bag'
        elif code == 0:  # stopped by someone: it closed its bag
            bag = f'its bag {bags[-1]} is closed'
        else:
            bag = f'its bag {bags[-1]} is unfinished: `zeus recover {bags[-1]}`'
        delay = self._delay(node)
        respawn = delay is not None
        self.gaps.append(f'{node.name} died at {when:.1f} s (exit code {code}); {bag}')
        base = re.sub(r'_respawn\d+$', '', bags[-1]) if bags else ''
        new_output = f'{base}_respawn{len(self.gaps)}' if bags else ''
        print(f'[zeus launch] {node.name} died with exit code {code}; the control loop keeps '
              f'running; {bag}; ' + (
                  f'restarting it into {new_output or "a new bag"} (steps until it records '
                  'again are not in any bag)' if respawn else
                  f'not restarting it again ({self._policy_text(node)}): the rest of the '
                  'run is not recorded'), file=sys.stderr, flush=True)
        if not respawn:
            self.nodes.remove(node)
            return
        node.argv = [*node.argv, '-p', f'output:={new_output}'] if new_output else node.argv
        node.lines = []
        node.restart_at = time.monotonic() + (delay or 0.0)
        self._restarted.add(node.name)

    def _give_up_recorder(self, node: NodeProcess, code: int) -> None:
        when = time.monotonic() - self.started
        self.gaps.append(f'{node.name} refused to restart at {when:.1f} s (exit code {code}); '
                         'the rest of the run is not recorded')
        print(f'[zeus launch] {node.name} exited with code {code} after a restart (it refused '
              'its parameters: see its error line); the control loop keeps running, the rest '
              'of the run is not recorded', file=sys.stderr, flush=True)
        self.nodes.remove(node)

    def _policy_text(self, node: NodeProcess) -> str:
        state = self.respawns.get(node.name)
        return 'never restarted' if state is None else state.policy.text()

    def unrecorded(self) -> list[str]:
        """What each recorder said it could not write (its closing 'not recorded:' line)."""
        found = []
        for node in self.nodes:
            if node.name in RECORDS_OTHERS:
                found += [f'{node.name} could not write {m.group(1)}'
                          for m in map(_NOT_RECORDED.search, node.lines) if m]
        return found

    def stop(self, grace: float = 10.0) -> dict[str, int]:
        """SIGINT every running node, wait up to `grace` seconds, then SIGTERM, then SIGKILL.

        Returns each node's exit code (and prints it), so a node that did not stop cleanly is
        named. A second Ctrl-C meanwhile is ignored: the nodes are already closing their files.
        """
        previous = {sig: signal.signal(sig, signal.SIG_IGN)
                    for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            self._stop(grace)
            return self._exit_codes()
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)

    def _stop(self, grace: float) -> None:
        deadline = time.monotonic() + grace
        # The recorder stops last, once the nodes it records are gone: it then holds every
        # step they published, not just those that arrived before the signal.
        producers = [node for node in self.nodes if node.name not in RECORDS_OTHERS]
        recorders = [node for node in self.nodes if node.name in RECORDS_OTHERS]
        for node in self.nodes:  # a restart still waiting: nothing to stop, none to start
            node.restart_at = None
        for group in (producers, recorders):
            if group is recorders and recorders and producers:
                time.sleep(RECORDER_DRAIN_S)  # the producers' last messages are still in flight
            stop_nodes([node.process for node in group if node.process is not None],
                       deadline=deadline)
            for node in group:
                if node.reader is not None:
                    node.reader.join(timeout=2)

    def _exit_codes(self) -> dict[str, int]:
        """Each node's exit code, printed on one line."""
        codes = {node.name: node.process.returncode for node in self.nodes
                 if node.process is not None}
        print('[zeus launch] exit codes: ' + ', '.join(f'{name} {code}'
                                                       for name, code in codes.items()),
              file=self.out, flush=True)
        return codes


def run_group(nodes: list[NodeProcess], env: dict[str, str], timeout: float | None = None,
              out: IO[str] = sys.stdout,
              policies: dict[str, RespawnPolicy] | None = None) -> int:
    """Start, supervise and stop a group; the exit code tells whether a node failed.

    SIGTERM (systemd, `timeout`, a supervisor) stops the group like Ctrl-C: the children run in
    their own sessions, so without this they would outlive the launcher and keep driving. SIGINT
    is taken explicitly too (as `ros2 launch` does): a launcher started as a background job of a
    script inherits SIGINT ignored and would otherwise never stop on `kill -INT`.
    """
    supervisor = Supervisor(nodes, env, out, policies)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _interrupt)
    try:
        supervisor.start()
        name, code = supervisor.wait(timeout)
    except KeyboardInterrupt:
        print('[zeus launch] Ctrl-C or SIGTERM: stopping all nodes', file=out, flush=True)
        codes = supervisor.stop()
        return _with_gaps(supervisor, 0 if not any(codes.values()) else 1)
    supervisor.stop()
    if name is None:
        print(f'[zeus launch] time limit of {timeout} s reached: stopped all nodes', file=out)
        return _with_gaps(supervisor, 0)
    if code != 0:
        print(f'[zeus launch] node {name!r} died with exit code {code}: stopped the others',
              file=sys.stderr, flush=True)
        return _with_gaps(supervisor, 1)
    print(f'[zeus launch] node {name!r} finished: stopped the others', file=out, flush=True)
    return _with_gaps(supervisor, 0)


def _interrupt(_signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def _with_gaps(supervisor: Supervisor, status: int) -> int:
    """Name every recording gap and restart at the end; a clean run with any exits 3."""
    gaps = supervisor.gaps + supervisor.unrecorded()
    if gaps:
        print(f'[zeus launch] the recording has {len(gaps)} gap(s): ' + '; '.join(gaps),
              file=sys.stderr, flush=True)
    if supervisor.restarts:
        print(f'[zeus launch] {len(supervisor.restarts)} restart(s): '
              + '; '.join(supervisor.restarts), file=sys.stderr, flush=True)
    return status or (RECORDING_GAPS if gaps or supervisor.restarts else 0)


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus launch`."""
    parser = ZeusArgumentParser(prog='zeus launch', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--params', type=Path, default=None,
                        help='ROS 2 params file for all nodes (/**/node_name: ros__parameters: '
                        f'...); default: the installed {launch_defaults.default_params_file()}')
    parser.add_argument('--nodes', default=','.join(launch_defaults.DEFAULT_NODES),
                        help=f'comma-separated subset of {",".join(NODES)}')
    parser.add_argument('--record', action='store_true', help='also start the recorder')
    parser.add_argument('--continual', action='store_true',
                        help='record, and retrain from the closed splits in the background: '
                        'each candidate is gated against the deployed checkpoint, swapped in '
                        'live on estimator and policy, rolled back on a live regression '
                        '(docs/usage.md, Continual deployment)')
    parser.add_argument('--robot', action='store_true',
                        help="robot_bridge in sim_bridge's place (--params: the robot's, e.g. "
                        'params/robot_bridge.yaml)')
    parser.add_argument('--task', default='',
                        help="task family to run (default: the params file's, Cheetah-Bias-v0): "
                        "its demo schedule and its zoo checkpoint (checkpoints/README.md)")
    parser.add_argument('--checkpoint', default='',
                        help="checkpoint for context_estimator and policy (default: the params "
                        "file's, or the --task family's zoo checkpoint)")
    parser.add_argument('--obs', default='', choices=[o for o in launch_defaults.OBS_CHOICES if o],
                        help='what the agent sees: pixels (sim_bridge renders frames, with '
                        "--robot the robot's camera; without --checkpoint the task's zoo pixel "
                        "checkpoint, experimental) or state (default: the params file's)")
    parser.add_argument('--log-level', default='info', choices=launch_defaults.LOG_LEVELS,
                        help='log level of every node')
    parser.add_argument('--domain-id', type=at_least(0, int, 232), default=None,
                        help='ROS_DOMAIN_ID for the group (default: $ROS_DOMAIN_ID or random)')
    parser.add_argument('--timeout', type=at_least(0.0, float), default=None,
                        help='stop everything after this many seconds')
    parser.add_argument('--namespace', default='',
                        help='run the group in this namespace (zeus/* topics move with it; '
                        '/diagnostics stays global, /clock too unless --sim-time: --clock)')
    parser.add_argument('--clock', default='',
                        help='with --sim-time: global (/clock), namespace (<namespace>/clock: '
                        'several simulated systems in one domain) or an absolute topic '
                        '(default: namespace with --namespace and --sim-time, else global)')
    parser.add_argument('--sim-time', action='store_true',
                        help='every node sets use_sim_time (sim_bridge publishes /clock)')
    parser.add_argument('--single-process', action='store_true',
                        help='sim_bridge, context_estimator and policy as nodes of one process '
                        'on one executor (default: a process each, so one crash is contained)')
    parser.add_argument('--no-intra-process', action='store_true',
                        help='with --single-process: messages between its nodes through DDS, '
                        'not handed over in process')
    parser.add_argument('--respawn', action='append', default=[], metavar='NODE=N[/W[/B]]',
                        help='restart NODE up to N times per W seconds (default 60), B seconds '
                        'after it died (default 1, doubling); N=0: never. Over the params '
                        "file's /**/zeus_launch respawn: section. Default: context_estimator, "
                        'policy and recorder 3/60/1 (recorder 0.5 s), the bridges never')
    parser.add_argument('--lock-parameters', action='store_true',
                        help='deployment: the bridges, estimator and policy declare their '
                        'safety-relevant parameters (action_timeout, noise, ...) read-only, so '
                        'no process can change them live; the checkpoint stays live')
    parser.add_argument('--no-progress', action='store_true',
                        help='no status line (steps, rate, episode, segment return; rewritten '
                        'in place on a terminal, a line every 10 s otherwise)')
    args = parser.parse_args(argv)
    names = [name.strip() for name in args.nodes.split(',') if name.strip()]
    try:
        launch = launch_defaults.plan(
            namespace=args.namespace, use_sim_time=args.sim_time, params_file=args.params,
            checkpoint=args.checkpoint, task=args.task, record=args.record,
            log_level=args.log_level,
            nodes=names, robot=args.robot, single_process=args.single_process,
            intra_process=not args.no_intra_process, continual=args.continual,
            clock=args.clock, obs=args.obs, lock_parameters=args.lock_parameters)
        known = [*NODES, CONTAINER]
        policies = parse_cli(args.respawn, known, policies_from_params(
            launch_defaults.read_params(launch.params_file), known))
        _verify_checkpoints(launch)
    except ValueError as error:
        print(f'zeus launch: {error}', file=sys.stderr)
        return 2
    clock = f'clock {launch.clock}; ' if launch.clock else ''  # every node remapped to it
    print(f'[zeus launch] params {launch.params_file}; {clock}' + '; '.join(
        f'{node.name} {node.parameters}' for node in launch.nodes if node.parameters),
        flush=True)
    env = {**ros_env(args.domain_id), **launch_defaults.launch_env()}  # + the pairing key
    if args.no_progress:
        return run_group(plan_processes(launch), env, args.timeout, policies=policies)
    from zeus_ros.system.launch_progress import Progress

    progress = Progress(env, launch.namespace)
    try:
        return run_group(plan_processes(launch), env, args.timeout, out=progress.out,
                         policies=policies)
    finally:
        progress.close()


def _verify_checkpoints(launch: LaunchPlan) -> None:
    """Refuse, before any node starts, a checkpoint the launch names that its record refutes.

    The nodes check it too (a params file's relative path is theirs to find); this spares a
    start-up that ends with every agent node exiting 2: a checkpoint whose sha256 differs from
    its record, or one trained for another family than the task its node (else the bridge)
    runs. IntegrityError is a ValueError; so is the mismatch, one line.
    """
    from zeus_ros.integrity import verify_file

    named = {str(node.parameters['checkpoint']): node.name for node in launch.nodes
             if node.name in AGENT_NODES and node.parameters.get('checkpoint')}
    for checkpoint, name in sorted(named.items()):
        if Path(checkpoint).is_absolute():
            verify_file(checkpoint)
            _check_task(launch, name, checkpoint)
    _check_student(launch)


def _check_student(launch: LaunchPlan) -> None:
    """ValueError (one line) for a pixel checkpoint the continual trainer cannot retrain.

    Not a teacher-head student, or its state teacher not found (continual_student.py): its
    rounds would each fail with that line after minutes of recording.
    """
    if not any(node.name == TRAINER for node in launch.nodes):
        return
    checkpoint = str(launch.parameter(TRAINER, 'checkpoint') or '')
    if not checkpoint or not Path(checkpoint).is_file():
        return
    from zeus_ros.offline.training.continual_student import state_teacher

    state_teacher(checkpoint)  # a StudentError is a ValueError


def _check_task(launch: LaunchPlan, name: str, checkpoint: str) -> None:
    """ValueError when `checkpoint` was trained for another task than node `name` will run."""
    from sim_bridge.registry import is_task_file

    task = launch.parameter(name, 'task') or launch.parameter('sim_bridge', 'task')
    if not task or is_task_file(str(task)):  # a task file: its node resolves the name
        return
    from zeus_ros.learning.checkpoint import stored_task
    from zeus_ros.learning.errors import CheckpointError

    try:
        stored = stored_task(checkpoint)
    except CheckpointError as error:
        raise ValueError(str(error)) from None
    if stored != task:
        raise ValueError(f"checkpoint {checkpoint} was trained for '{stored}', but {name} "
                         f"runs '{task}': nothing started; pass --task {stored}, or a "
                         f'checkpoint trained for {task}')


if __name__ == '__main__':
    raise SystemExit(main())
