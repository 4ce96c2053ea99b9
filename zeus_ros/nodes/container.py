r"""Several zeus_ros nodes in one process on one executor: the Python component container.

    python -m zeus_ros.nodes.container [--no-intra-process] --ros-args --log-level info \\
        --node sim_bridge --ros-args --params-file F -r __ns:=/r1 -p min_observers:=2 \\
        --node context_estimator --ros-args --params-file F -r __ns:=/r1 \\
        --node policy --ros-args --params-file F -r __ns:=/r1

Why: in one process the step messages never cross a process boundary, torch is loaded once and
the three nodes share one executor (`zeus launch --single-process`). Each node gets exactly the
`--ros-args` it gets as a process of its own (params file, namespace, remaps, `-p` overrides) as
its Node's `cli_args`, and is built by its own class, so names, parameters and behaviour are the
same in both modes. The arguments before the first `--node` are the process's (log level).
A node that stops (sim_bridge's max_steps) or a Ctrl-C stops them all (spin.run_nodes).

Messages between the nodes are handed over as Python objects (intra-process delivery,
nodes/intra_process.py) and still published on DDS for everyone outside; `--no-intra-process`
sends them through DDS only, as between processes. The container spins on the executor
$ZEUS_EXECUTOR names, as every node process does (nodes/spin.make_executor).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import functools
import importlib
import sys
from typing import TYPE_CHECKING

from zeus_ros.nodes.intra_process import IntraProcessBus, with_intra_process
from zeus_ros.nodes.spin import run_nodes
from zeus_ros.system.launch_defaults import CONTAINER_NO_INTRA, NODES

if TYPE_CHECKING:
    from rclpy.node import Node

NODE_FLAG = '--node'
NODE_CLASSES = {
    'sim_bridge': 'SimBridgeNode',
    'context_estimator': 'ContextEstimatorNode',
    'policy': 'PolicyNode',
    'recorder': 'RecorderNode',
    'robot_bridge': 'RobotBridgeNode',
}
"""Node name (launch_defaults.NODES) -> its class in that module."""


def parse_container_args(argv: Sequence[str]) -> tuple[list[str], list[tuple[str, list[str]]]]:
    """Split argv into the process's arguments and (node name, that node's --ros-args) pairs.

    Raises ValueError (one line) for an unknown node, a node given twice or none at all.
    """
    process: list[str] = []
    nodes: list[tuple[str, list[str]]] = []
    args = list(argv)
    while args:
        item = args.pop(0)
        if item != NODE_FLAG:
            (nodes[-1][1] if nodes else process).append(item)
            continue
        if not args:
            raise ValueError(f'{NODE_FLAG} needs a node name, one of {", ".join(NODE_CLASSES)}')
        name = args.pop(0)
        if name not in NODE_CLASSES:
            raise ValueError(f'{NODE_FLAG} {name}: unknown node; choose from '
                             f'{", ".join(NODE_CLASSES)}')
        if any(name == known for known, _args in nodes):
            raise ValueError(f'{NODE_FLAG} {name} is given twice (one process holds each node '
                             'once: their names would clash)')
        nodes.append((name, []))
    if not nodes:
        raise ValueError(f'no node to run: give {NODE_FLAG} NAME --ros-args ... per node')
    return process, nodes


def node_factory(name: str, cli_args: Sequence[str], bus: IntraProcessBus | None = None
                 ) -> Callable[[], Node]:
    """Build node `name` with its own class and its own command-line arguments.

    With `bus`, the node delivers to and receives from the other nodes on it in process.
    """
    module = importlib.import_module(NODES[name])
    node_class = getattr(module, NODE_CLASSES[name])
    if bus is not None:
        node_class = with_intra_process(node_class, bus)
    return functools.partial(node_class, cli_args=list(cli_args))


def main(args: list[str] | None = None) -> int:
    """Entry point of `ros2 run zeus_ros loop_container` and `python -m` this module."""
    argv = sys.argv[1:] if args is None else args
    try:
        process, nodes = parse_container_args(argv)
    except ValueError as error:
        print(f'loop_container: {error}', file=sys.stderr)
        return 2
    bus = None if CONTAINER_NO_INTRA in process else IntraProcessBus()
    process = [arg for arg in process if arg != CONTAINER_NO_INTRA]
    factories = [node_factory(name, node_args, bus) for name, node_args in nodes]
    return run_nodes(factories, [sys.argv[0], *process])


if __name__ == '__main__':
    raise SystemExit(main())
