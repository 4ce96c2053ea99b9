"""The platform's floor for one hand-over between nodes, and the live-loop ratio it allows.

Why: every step of the live loop passes three hand-overs in turn (StepFeedback to the estimator,
its context to the policy, the action back to sim_bridge), each a publish, a delivery and a
callback in another node. Rings of relays that do nothing else measure what one hand-over costs
on this machine: n members in a ring, each passing on at once what it got; one round is n
hand-overs, so a hand-over costs round time / n. Rings:

- `pipe`: n processes joined by OS pipes (the kernel's wake-up and copy, no ROS);
- `rclpy-<executor>`: n processes, one rclpy node each, reliable keep-last topics (step_qos) on
  DDS, spinning on the executor the nodes use ($ZEUS_EXECUTOR: `single` or `events`);
- `one-process-dds`: n nodes of one process on one executor, every message through DDS (as
  `zeus launch --single-process --no-intra-process`);
- `one-process-bus`: the same nodes with the container's intra-process bus (as
  `zeus launch --single-process`);
- a name ending in `+sender`: the links into sim_bridge's and the policy's places go through
  `SenderSubscription`s (nodes/senders.py), as those nodes take actions and contexts.

Then what that leaves of the in-process rate: with W the in-process state loop's period
(bench_live_loop.in_process_rate, the work of the three nodes, no messages) and h a hand-over,
a loop of three hand-overs runs at most at W / (W + 3h) of the in-process rate. Each ring is
then run again with its members working (a busy loop, no sleep) as long as each node's part of
W in process, sim_bridge's, the estimator's, the policy's in ring order: the ratio a live loop
would reach if its nodes did exactly their in-process work and paid the platform's hand-overs,
and h under that load. Last, how long one `publish()` holds its caller with 0, 1 and 2
subscriber processes matched: each reader outside costs the publisher, whatever the layout.
`--payload-bytes` sizes each message's float array (0: an Action without data; 21168: one
84x84 RGB frame's bytes, what a pixel step carries). Rings start with their own rclpy
context; relays loop on `spin_once`, as the nodes do (rclpy's EventsExecutor.spin() delivered
nothing in a relay here and ignored SIGTERM).

    source scripts/env.sh && python benchmarks/bench_handover.py [--rounds 3000] \
        [--payload-bytes 0,21168] [--rings pipe,rclpy-events,...] [--csv out.csv]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
import csv
import multiprocessing
import os
from pathlib import Path
import sys
import tempfile
import time
from typing import Any, NamedTuple

from bench_live_loop import (  # puts the repo on the path
    cpu_seconds,
    in_process_rate,
    make_checkpoint,
)
import numpy as np

LOOP_HANDOVERS = 3
"""Hand-overs in turn per live-loop step: sim_bridge -> estimator -> policy -> sim_bridge."""
RINGS = ('pipe', 'rclpy-single', 'rclpy-events', 'rclpy-events+sender', 'one-process-dds',
         'one-process-bus', 'one-process-bus+sender')
START_TIMEOUT = 60.0
"""Seconds a ring may take to carry its first message (discovery of n processes)."""


def link_topic(index: int) -> str:
    """The topic from ring member `index` to the next (a name token may not start with a digit)."""
    return f'/handover_ring/link_{index}'


def _pipe_member(inbox: Any, outbox: Any, work: float) -> None:
    """Pass on every message after `work` s of work, until an empty one (passed on too)."""
    while message := inbox.recv_bytes():
        busy(work)
        outbox.send_bytes(message)
    outbox.send_bytes(message)


class Round(NamedTuple):
    """One round of a ring: wall-clock seconds, and CPU seconds of all members together."""

    wall: float
    cpu: float


def pipe_ring(rounds: int, payload_bytes: int, work: Sequence[float]) -> Round:
    """A round of a ring of len(work) processes joined by pipes."""
    members = len(work)
    spawn = multiprocessing.get_context('spawn')
    pipes = [spawn.Pipe(duplex=False) for _ in range(members)]  # pipes[i]: member i -> i + 1
    children = [spawn.Process(target=_pipe_member, args=(pipes[i - 1][0], pipes[i][1], work[i]))
                for i in range(1, members)]
    for child in children:
        child.start()
    inbox, outbox = pipes[members - 1][0], pipes[0][1]
    message = b'x' * max(1, payload_bytes)
    outbox.send_bytes(message)  # one round to start every member
    inbox.recv_bytes()
    def cpu() -> float:
        return time.process_time() + sum(cpu_seconds(child.pid) for child in children)
    cpu_start, start = cpu(), time.perf_counter()
    for _ in range(rounds):
        busy(work[0])
        outbox.send_bytes(message)
        inbox.recv_bytes()
    elapsed, cpu_used = time.perf_counter() - start, cpu() - cpu_start
    outbox.send_bytes(b'')
    inbox.recv_bytes()
    for child in children:
        child.join(timeout=10)
    return Round(elapsed / rounds, cpu_used / rounds)


def _message(payload_bytes: int) -> Any:
    from zeus_msgs.msg import Action

    message = Action()
    if payload_bytes:
        message.data = np.zeros(payload_bytes // 4, np.float32)
    return message


class _Ring:
    """Member 0 of a ring: injects step k, times the rounds, passes the next step on arrival."""

    def __init__(self, node: Any, members: int, rounds: int, payload_bytes: int,
                 work: float = 0.0, sender: bool = False) -> None:
        from zeus_msgs.msg import Action

        from zeus_ros.nodes.topics import step_qos

        self.rounds, self.work = rounds, work
        self.message = _message(payload_bytes)
        self.step = 0  # steps below 1 are warm-up injections, re-sent until one comes round
        self.started = self.finished = 0.0
        self.publisher = node.create_publisher(Action, link_topic(0), step_qos())
        subscribe(node, link_topic(members - 1), self.on_message, sender)

    def inject(self) -> None:
        """Send the warm-up message again until the ring is matched end to end."""
        if self.step == 0:
            self.publisher.publish(self.message)

    def on_message(self, message: Any) -> None:
        if message.step != self.step or self.finished:
            return  # a duplicate warm-up message
        if self.step == 0:
            self.started = time.perf_counter()
        elif self.step == self.rounds:
            self.finished = time.perf_counter()
            return
        self.step += 1
        self.message.step = self.step
        busy(self.work)
        self.publisher.publish(self.message)


def busy(seconds: float) -> None:
    """Hold the CPU for `seconds`, as a node's own work does (not a sleep: no wake-up)."""
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def subscribe(node: Any, topic: str, callback: Any, sender: bool) -> None:
    """A plain subscription, or (`sender`) a SenderSubscription.

    sim_bridge and the policy take actions and contexts through one (nodes/senders.py).
    """
    from zeus_msgs.msg import Action

    from zeus_ros.nodes.senders import SenderSubscription
    from zeus_ros.nodes.topics import step_qos

    if sender:
        SenderSubscription(node, Action, topic, step_qos(), callback, admit=lambda _gid: True)
    else:
        node.create_subscription(Action, topic, callback, step_qos())


def _relay(node: Any, index: int, members: int, work: float = 0.0, sender: bool = False
           ) -> None:
    """Member `index` > 0: works `work` s on what arrives on the link before it, passes it on.

    `sender`: the last member (the policy's place) takes through a SenderSubscription.
    """
    from zeus_msgs.msg import Action

    from zeus_ros.nodes.topics import step_qos

    publisher = node.create_publisher(Action, link_topic(index), step_qos())

    def on_message(message: Any) -> None:
        busy(work)
        publisher.publish(message)
    subscribe(node, link_topic(index - 1), on_message, sender and index == members - 1)


def _spin_ring(executor: Any, ring: _Ring, cpu: Callable[[], float]) -> Round:
    """Spin until the ring has done its rounds; `cpu`: the members' CPU seconds so far."""
    deadline = time.monotonic() + START_TIMEOUT
    while not ring.started:
        if time.monotonic() > deadline:
            raise RuntimeError(f'the ring carried no message in {START_TIMEOUT:.0f} s: '
                               'its members did not discover each other')
        ring.inject()
        executor.spin_once(timeout_sec=0.05)
    cpu_start = cpu()  # a round or so after the start: a small part of the rounds
    while not ring.finished:
        executor.spin_once(timeout_sec=1.0)
    return Round((ring.finished - ring.started) / ring.rounds, (cpu() - cpu_start) / ring.rounds)


@contextmanager
def _helpers(argvs: Sequence[Sequence[str]], env: dict[str, str]) -> Iterator[list[Any]]:
    """Child processes of this script (relays, sinks), stopped on leaving; their log in /tmp."""
    from zeus_ros.system.processes import start_node, stop_nodes

    with (Path(tempfile.gettempdir()) / 'zeus_bench_handover.log').open('w') as log:
        children = [start_node([sys.executable, __file__, *argv], env, stdout=log)
                    for argv in argvs]
        try:
            yield children
        finally:
            stop_nodes(children, deadline=time.monotonic() + 10)


def rclpy_ring(rounds: int, payload_bytes: int, work: Sequence[float], executor_kind: str,
               sender: bool = False) -> Round:
    """A round of a ring of len(work) processes, one rclpy node each."""
    import rclpy

    from zeus_ros.nodes.spin import EXECUTOR_ENV, make_executor
    from zeus_ros.system.processes import ros_context, ros_env

    env = ros_env()  # $ROS_DOMAIN_ID, else one from $ZEUS_DOMAIN_RANGE; loopback only
    env[EXECUTOR_ENV] = executor_kind
    members = len(work)
    argvs = [['--relay', str(index), '--members', str(members), '--relay-work', str(work[index]),
              *(['--relay-sender'] if sender else [])] for index in range(1, members)]
    with _helpers(argvs, env) as relays, ros_context(int(env['ROS_DOMAIN_ID'])) as context:
        node = rclpy.create_node('handover_0', context=context)
        ring = _Ring(node, members, rounds, payload_bytes, work[0], sender)
        executor = make_executor([node], executor_kind, context)
        timing = _spin_ring(executor, ring, lambda: time.process_time() + sum(
            cpu_seconds(relay.pid) for relay in relays))
        executor.shutdown()
        node.destroy_node()
    return timing


def one_process_ring(rounds: int, payload_bytes: int, work: Sequence[float], bus: bool,
                     sender: bool = False) -> Round:
    """A round of a ring of len(work) nodes of one process on one executor."""
    from rclpy.node import Node

    from zeus_ros.nodes.intra_process import IntraProcessBus, with_intra_process
    from zeus_ros.nodes.spin import make_executor
    from zeus_ros.system.processes import ros_context, ros_env

    node_class = with_intra_process(Node, IntraProcessBus()) if bus else Node
    with ros_context(int(ros_env()['ROS_DOMAIN_ID'])) as context:
        members = len(work)
        nodes = [node_class(f'handover_{index}', context=context) for index in range(members)]
        ring = _Ring(nodes[0], members, rounds, payload_bytes, work[0], sender)
        for index in range(1, members):
            _relay(nodes[index], index, members, work[index], sender)
        executor = make_executor(nodes, context=context)
        timing = _spin_ring(executor, ring, time.process_time)
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
    return timing


def relay_main(index: int, members: int, work: float, sender: bool) -> None:
    """A ring member in its own process (the --relay entry point), until stopped."""
    import rclpy

    from zeus_ros.nodes.spin import make_executor

    rclpy.init()
    node = rclpy.create_node(f'handover_{index}_{os.getpid()}')  # publish_cost runs several
    _relay(node, index, members, work, sender)
    executor = make_executor([node])
    try:  # spin_once, as the nodes: rclpy's EventsExecutor.spin() delivered nothing here
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        rclpy.try_shutdown()


def publish_cost(readers: int, rounds: int, payload_bytes: int, gap: float = 1e-3) -> float:
    """Seconds one publish() holds its caller with `readers` subscriber processes matched.

    Published every `gap` s (the caller busy in between, as a node working), not back to
    back, so each reader has taken the previous message.
    """
    import rclpy
    from zeus_msgs.msg import Action

    from zeus_ros.nodes.topics import step_qos
    from zeus_ros.system.processes import ros_context, ros_env

    env = ros_env()
    sink = ['--relay', '1', '--members', '2']  # a relay whose link onwards nobody reads
    with _helpers([sink] * readers, env), ros_context(int(env['ROS_DOMAIN_ID'])) as context:
        node = rclpy.create_node('publisher', context=context)
        publisher = node.create_publisher(Action, link_topic(0), step_qos())
        deadline = time.monotonic() + START_TIMEOUT
        while publisher.get_subscription_count() < readers:
            if time.monotonic() > deadline:
                raise RuntimeError(f'{readers} readers did not match in {START_TIMEOUT:.0f} s')
            time.sleep(0.05)
        time.sleep(0.5)  # the readers' own discovery settles
        message, held = _message(payload_bytes), 0.0
        for step in range(rounds):
            message.step = step
            start = time.perf_counter()
            publisher.publish(message)
            held += time.perf_counter() - start
            busy(gap)
        node.destroy_node()
    return held / rounds


def ring_round(ring: str, rounds: int, payload_bytes: int, work: Sequence[float]) -> Round:
    """A round of the ring named `ring` (RINGS), member i working work[i] s.

    A name ending in `+sender` takes the links into sim_bridge's and the policy's places
    through SenderSubscriptions, as those nodes do.
    """
    base, sender = ring.removesuffix('+sender'), ring.endswith('+sender')
    if base == 'pipe' and not sender:
        return pipe_ring(rounds, payload_bytes, work)
    if base in ('rclpy-single', 'rclpy-events'):
        return rclpy_ring(rounds, payload_bytes, work, base.removeprefix('rclpy-'), sender)
    if base in ('one-process-dds', 'one-process-bus'):
        return one_process_ring(rounds, payload_bytes, work, base.endswith('bus'), sender)
    raise ValueError(f'unknown ring {ring!r}: one of {", ".join(RINGS)}')


def loop_bound(period: float, handover: float) -> float:
    """The highest ratio to the in-process rate a loop of LOOP_HANDOVERS hand-overs can reach."""
    return period / (period + LOOP_HANDOVERS * handover)


def in_process_parts(steps: int) -> tuple[float, dict[str, float]]:
    """The in-process state loop's period and each node's part of it, in seconds."""
    with tempfile.TemporaryDirectory() as tmp:
        checkpoint = make_checkpoint(Path(tmp) / 'state.pt', 'state')
        rate, _, parts = in_process_rate(checkpoint, steps)
    return 1.0 / rate, {name: ms * 1e-3 for name, ms in parts.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rounds', type=int, default=3000)
    parser.add_argument('--members', type=int, default=LOOP_HANDOVERS)
    parser.add_argument('--payload-bytes', default='0,21168')
    parser.add_argument('--rings', default=','.join(RINGS))
    parser.add_argument('--in-process-steps', type=int, default=1000,
                        help='steps of the in-process state loop that gives W (0: skip)')
    parser.add_argument('--csv', type=Path, default=None)
    parser.add_argument('--relay', type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument('--relay-work', type=float, default=0.0, help=argparse.SUPPRESS)
    parser.add_argument('--relay-sender', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.relay is not None:
        relay_main(args.relay, args.members, args.relay_work, args.relay_sender)
        return
    rings = args.rings.split(',')
    rows = []
    for payload in (int(b) for b in args.payload_bytes.split(',')):
        for ring in rings:
            timing = ring_round(ring, args.rounds, payload, [0.0] * args.members)
            rows.append({'ring': ring, 'payload_bytes': payload, 'work_ms': 0.0,
                         'round_ms': timing.wall * 1e3,
                         'handover_us': timing.wall / args.members * 1e6,
                         'cpu_per_handover_us': timing.cpu / args.members * 1e6})
            print(f'{ring:>22} payload {payload:>6} B: {rows[-1]["handover_us"]:6.1f} us per '
                  f'hand-over, CPU {rows[-1]["cpu_per_handover_us"]:6.1f} us', flush=True)
    for payload in (int(b) for b in args.payload_bytes.split(',')):
        costs = [publish_cost(readers, args.rounds, payload) for readers in (0, 1, 2)]
        rows.extend({'ring': f'publish-{readers}-readers', 'payload_bytes': payload,
                     'publish_us': cost * 1e6} for readers, cost in enumerate(costs))
        print(f'publish() with 0 / 1 / 2 subscriber processes, payload {payload} B: '
              f'{" / ".join(f"{cost * 1e6:.1f}" for cost in costs)} us in the call', flush=True)
    if args.in_process_steps and args.members == LOOP_HANDOVERS:
        period, parts = in_process_parts(args.in_process_steps)
        work = [parts['sim_bridge'], parts['estimator'], parts['policy']]  # ring order
        print(f'in-process state loop: {1 / period:.0f} steps/s, W = {period * 1e3:.2f} ms '
              f'(sim_bridge {work[0] * 1e3:.2f}, estimator {work[1] * 1e3:.2f}, policy '
              f'{work[2] * 1e3:.2f}); ratio to it of a loop of {LOOP_HANDOVERS} hand-overs:')
        print(f'{"":>22}  W/(W+3h)  members working as in process: ratio, h, CPU per '
              'hand-over beyond the work')
        for ring in rings:
            handover = next(row['handover_us'] for row in rows
                            if row['ring'] == ring and row['payload_bytes'] == 0) * 1e-6
            timing = ring_round(ring, args.rounds, 0, work)
            loaded = (timing.wall - sum(work)) / LOOP_HANDOVERS
            cpu = (timing.cpu - sum(work)) / LOOP_HANDOVERS
            rows.append({'ring': ring, 'payload_bytes': 0, 'work_ms': sum(work) * 1e3,
                         'round_ms': timing.wall * 1e3, 'handover_us': loaded * 1e6,
                         'cpu_per_handover_us': cpu * 1e6,
                         'ratio_to_in_process': period / timing.wall})
            print(f'{ring:>22}  {loop_bound(period, handover):>7.2f}x  '
                  f'{period / timing.wall:>8.2f}x, {loaded * 1e6:6.1f} us, {cpu * 1e6:6.1f} us',
                  flush=True)
    if args.csv:
        with args.csv.open('w', newline='') as out:
            fields = list(dict.fromkeys(key for row in rows for key in row))
            writer = csv.DictWriter(out, fieldnames=fields, restval='')
            writer.writeheader()
            writer.writerows(rows)


if __name__ == '__main__':
    main()
