"""recorder node and `zeus recover`: real processes, SIGINT / SIGKILL, bags read back."""

from __future__ import annotations

from pathlib import Path
import signal
import time
from typing import TYPE_CHECKING, Any

import pytest
from rosbags.highlevel import AnyReader

from zeus_ros.bags.recover import STEP_TOPICS
from zeus_ros.cli import recover
from zeus_ros.offline.data.ingest import ingest_bags

from ros_harness import driver_node as ros_node
from ros_harness import python_module, spin_until

if TYPE_CHECKING:
    from ros_harness import ProcessGroup

pytestmark = [pytest.mark.ros, pytest.mark.slow]

PERIOD = 0.01
"""Seconds between published steps (100 Hz, a fast control rate)."""


class StepPublisher:
    """Publishes what sim_bridge, context_estimator and policy publish for one control step."""

    def __init__(self, node: Any) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from zeus_msgs.msg import Action, ContextEstimate, ContextTruth, StateVector, StepFeedback

        from zeus_ros.nodes.topics import TOPICS

        self.node = node
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                         reliability=ReliabilityPolicy.RELIABLE)
        self.types = {TOPICS.CLOCK: Clock, TOPICS.CONTEXT_TRUTH: ContextTruth,
                      TOPICS.STEP: StepFeedback, TOPICS.STATE: StateVector,
                      TOPICS.CONTEXT: ContextEstimate, TOPICS.ACTION: Action}
        self.pubs = {t: node.create_publisher(cls, t, qos) for t, cls in self.types.items()}
        self.diagnostics: dict[str, str] = {}
        node.create_subscription(DiagnosticArray, TOPICS.DIAGNOSTICS, self._on_diag, 10)

    def _on_diag(self, msg: Any) -> None:
        for status in msg.status:
            if status.name.lstrip('/').startswith('recorder'):
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def wait_for_recorder(self, timeout: float = 15.0) -> None:
        """Block until the recorder subscribes to every topic (no message goes unheard)."""
        assert spin_until(self.node, lambda: all(
            p.get_subscription_count() > 0 for p in self.pubs.values()), timeout)

    def publish(self, step: int, last: bool = False) -> None:
        """Publish step `step` of one episode, every message with the same stamp."""
        from zeus_ros.nodes.messages import stamp_from_seconds
        from zeus_ros.nodes.topics import TOPICS

        stamp = stamp_from_seconds(step * 0.05)
        msgs = {t: cls() for t, cls in self.types.items()}
        msgs[TOPICS.CLOCK].clock = stamp
        for topic, msg in msgs.items():
            if topic == TOPICS.CLOCK:
                continue
            msg.header.stamp = stamp
            msg.header.frame_id = 'world'
            msg.step = step
        truth = msgs[TOPICS.CONTEXT_TRUTH]
        truth.names, truth.values, truth.segment = ['mass'], [1.0 + step * 1e-3], 0
        fb = msgs[TOPICS.STEP]
        fb.episode, fb.episode_step, fb.first, fb.last = 0, step, step == 0, last
        fb.reward, fb.task = 0.5, 'Cheetah-Run-v0'
        fb.applied_action = [] if step == 0 else [0.1] * 6
        fb.action_status = 0 if step == 0 else 1
        msgs[TOPICS.STATE].data = [float(step)] * 17
        msgs[TOPICS.CONTEXT].data, msgs[TOPICS.CONTEXT].history_length = [0.0] * 8, 1
        msgs[TOPICS.ACTION].data = [0.1] * 6
        for topic in (TOPICS.CLOCK, TOPICS.CONTEXT_TRUTH, TOPICS.STEP, TOPICS.STATE,
                      TOPICS.CONTEXT, TOPICS.ACTION):  # sim_bridge order, then the agent
            self.pubs[topic].publish(msgs[topic])

    def run(self, steps: int, should_stop: Any = None) -> list[float]:
        """Publish `steps` steps at PERIOD; return each step's publish time (monotonic)."""
        times: list[float] = []
        for step in range(steps):
            if should_stop is not None and should_stop():
                break
            self.publish(step, last=step == steps - 1)
            times.append(time.monotonic())
            time.sleep(PERIOD)
        return times


def start_recorder(group: ProcessGroup, output: Path, *params: str) -> Any:
    """Start the recorder node writing to `output` with extra `name:=value` parameters."""
    args = ['--ros-args', '-p', f'output:={output}']
    for param in params:
        args += ['-p', param]
    return group.start(f'recorder-{output.parent.name}', python_module(
        'zeus_ros.nodes.recorder_node', *args))


def steps_per_topic(bags: list[Path]) -> dict[str, set[int]]:
    """The step indices found on each step-carrying topic of the bags."""
    found: dict[str, set[int]] = {t: set() for t in STEP_TOPICS}
    with AnyReader(bags) as reader:
        for conn, _, raw in reader.messages():
            if conn.topic in STEP_TOPICS:
                found[conn.topic].add(int(reader.deserialize(raw, conn.msgtype).step))
    return found


def test_sigint_closes_a_bag_holding_every_step(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """SIGINT after 300 steps leaves a closed mcap bag with all of them, readable by ingest.

    The metadata is Jazzy's: version 9, the QoS the publishers offered and their type hashes,
    as the ROS graph reports them.
    """
    from ruamel.yaml import YAML

    out = tmp_path / 'run'
    recorder = start_recorder(ros_processes, out)
    with ros_node(ros_processes.domain_id) as node:
        pub = StepPublisher(node)
        pub.wait_for_recorder()
        pub.run(300)
        key = 'messages /zeus/action'
        assert spin_until(node, lambda: pub.diagnostics.get(key) == '300', 10.0), pub.diagnostics
        assert pub.diagnostics['gaps /zeus/observation/state'] == '0'
        [graph] = node.get_publishers_info_by_topic('/zeus/step')
    assert ros_processes.stop(recorder, signal.SIGINT) == 0, ros_processes.log_text(
        f'recorder-{tmp_path.name}')
    bag = out / 'run_000'
    assert (bag / 'run_000.mcap').read_bytes()[-8:] == b'\x89MCAP0\r\n'
    info = YAML(typ='safe').load((bag / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    assert (info['version'], info['ros_distro']) == (9, 'jazzy')
    [step] = [t['topic_metadata'] for t in info['topics_with_message_count']
              if t['topic_metadata']['name'] == '/zeus/step']
    assert step['type_description_hash'] == str(graph.topic_type_hash)
    [qos] = step['offered_qos_profiles']
    assert (qos['reliability'], qos['durability'], qos['history']) == (
        'reliable', 'volatile', graph.qos_profile.history.name.lower())
    assert all(s == set(range(300)) for s in steps_per_topic([bag]).values())
    data = ingest_bags(out, strict=True)
    assert data.num_transitions == 299


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_sigkill_then_recover_keeps_all_but_the_last_second(
        ros_processes: ProcessGroup, tmp_path: Path, storage: str) -> None:
    """After SIGKILL, `zeus recover` restores every step published over 1 s before the kill."""
    out = tmp_path / 'run'
    recorder = start_recorder(ros_processes, out, f'storage:={storage}')
    with ros_node(ros_processes.domain_id) as node:
        pub = StepPublisher(node)
        pub.wait_for_recorder()
        start = time.monotonic()
        times = pub.run(10_000, should_stop=lambda: time.monotonic() - start > 3.0)
        killed_at = time.monotonic()
        ros_processes.stop(recorder, signal.SIGKILL)
    assert recover.main([str(out)]) == 0
    found = steps_per_topic([out / 'run_000'])
    old = {step for step, t in enumerate(times) if t < killed_at - 1.1}
    assert len(old) > 100
    for topic, steps in found.items():
        assert old <= steps, f'{topic}: lost {sorted(old - steps)[:5]}...'
    assert recover.main([str(out)]) == 0  # a recovered bag is left as it is


def test_split_by_size_keeps_each_step_in_one_bag(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """split_size_mb cuts several bags, every step whole in exactly one of them."""
    out = tmp_path / 'run'
    recorder = start_recorder(ros_processes, out, 'split_size_mb:=0.02')
    with ros_node(ros_processes.domain_id) as node:
        pub = StepPublisher(node)
        pub.wait_for_recorder()
        pub.run(200)
        assert spin_until(node, lambda: pub.diagnostics.get('messages /zeus/action') == '200',
                          10.0)
    assert ros_processes.stop(recorder, signal.SIGTERM) == 0
    bags = sorted(p for p in out.iterdir() if p.is_dir())
    assert len(bags) >= 3
    per_bag = [steps_per_topic([bag]) for bag in bags]
    for found in per_bag:
        assert len({frozenset(s) for s in found.values()}) == 1, 'a step was cut in two'
    assert sorted(s for f in per_bag for s in f['/zeus/step']) == list(range(200))


@pytest.mark.parametrize(('param', 'named'), [
    ('flush_period_s:=0.0', 'flush_period_s'),
    ('storage:=rosbag', 'storage'),
    ('topics:=[/zeus/nope]', 'topics'),
])
def test_bad_parameter_fails_at_start_naming_it(
        ros_processes: ProcessGroup, tmp_path: Path, param: str, named: str) -> None:
    """A bad parameter value exits with code 2 and a message naming the parameter."""
    out = tmp_path / 'run'
    recorder = start_recorder(ros_processes, out, param)
    assert recorder.wait(timeout=20) == 2
    assert f'parameter {named}' in ros_processes.log_text(f'recorder-{tmp_path.name}')
    assert not out.exists()


def test_the_steps_wait_until_the_expected_publishers_are_heard(
        ros_processes: ProcessGroup, tmp_path: Path) -> None:
    """expected_publishers: zeus/step (the loop's go-ahead) only once the recorder hears them.

    A recorder that expects context and action publishers does not subscribe to the steps
    while neither exists (so a step source waiting for it cannot start), nor with only the
    context publisher; after publisher_timeout it names the topic still unheard and subscribes
    anyway. A second recorder expecting only the context publisher, which exists, subscribes
    at once. (A launch sets it: `zeus launch --record`, the demo.)
    """
    from zeus_msgs.msg import ContextEstimate

    def step_readers(node: Any) -> list[str]:
        return sorted(info.node_name for info in node.get_subscriptions_info_by_topic(
            '/zeus/step'))

    out = tmp_path / 'late' / 'bag'
    started = time.monotonic()  # the recorder's timeout runs from later: its own start
    start_recorder(ros_processes, out, "expected_publishers:=['/zeus/context','/zeus/action']",
                   'publisher_timeout:=12.0')
    with ros_node(ros_processes.domain_id) as node:
        assert spin_until(node, lambda: node.count_subscribers('/zeus/context') == 1, 60.0)
        assert not spin_until(node, lambda: bool(step_readers(node)), 2.0), step_readers(node)
        node.create_publisher(ContextEstimate, '/zeus/context', 10)
        assert not spin_until(node, lambda: bool(step_readers(node)), 2.0), step_readers(node)
        assert spin_until(node, lambda: step_readers(node) == ['recorder'], 60.0)
        assert time.monotonic() - started > 12.0  # the timeout, not a match, let it go on
        log = ros_processes.log_text(f'recorder-{out.parent.name}')
        assert 'publisher_timeout: 12 s passed waiting for /zeus/action (0 of 1 publishers ' \
            'matched); subscribing to the steps anyway' in log, log
        timed_out = next(line for line in log.splitlines() if 'publisher_timeout:' in line)
        assert '/zeus/context (' not in timed_out, log  # heard by then: not named
        other = tmp_path / 'heard' / 'bag'
        ros_processes.start('recorder-heard', python_module(
            'zeus_ros.nodes.recorder_node', '--ros-args', '-r', '__node:=recorder2', '-p',
            f'output:={other}', '-p', "expected_publishers:=['/zeus/context']"))
        assert spin_until(node, lambda: step_readers(node) == ['recorder', 'recorder2'], 30.0)
    bad = start_recorder(ros_processes, tmp_path / 'bad' / 'bag',
                         "expected_publishers:=['/zeus/novelty']")
    assert bad.wait(timeout=60) == 2
    assert "expected_publishers names ['/zeus/novelty'], which it does not record" in \
        ros_processes.log_text('recorder-bad')
