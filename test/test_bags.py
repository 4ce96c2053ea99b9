"""Bags: collect -> ingest round trip, corrupt bags, gaps and duplicates."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from zeus_ros.bags.errors import BagError, IngestError
from zeus_ros.bags.schema import (
    TOPIC_ACTION,
    TOPIC_CONTEXT_TRUTH,
    TOPIC_IMAGE,
    TOPIC_STATE,
    TOPIC_STEP,
    StepFeedbackFields,
    codec,
)
from zeus_ros.bags.writer import StepBagWriter
from zeus_ros.offline.data.ingest import IngestWarning, Issue, ingest_bags

EP_LEN = 5


@dataclass
class Faults:
    """Messages to drop, duplicate or re-stamp when writing a synthetic bag."""

    drop: set[tuple[str, int]] = field(default_factory=set)
    dup: set[tuple[str, int]] = field(default_factory=set)
    shift: set[tuple[str, int]] = field(default_factory=set)
    nan: set[tuple[str, int]] = field(default_factory=set)
    """The message's vector holds a NaN."""
    short: set[tuple[str, int]] = field(default_factory=set)
    """The message's vector has one value fewer."""


VECTORS = {TOPIC_STATE: 'data', TOPIC_STEP: 'applied_action', TOPIC_CONTEXT_TRUTH: 'values',
           TOPIC_ACTION: 'data'}


def _write_synthetic(path: Path, steps: int, faults: Faults | None = None,
                     storage: str = 'mcap', images: Sequence[tuple[int, bytes]] = ()) -> Path:
    """Write `steps` steps of a 2-d toy run (episodes of EP_LEN transitions) message by message.

    `images`: (stamp, CDR) of /zeus/observation/image messages, written after the steps in
    that order (step k has stamp 1_000_000 * (k + 1)).
    """
    faults = faults or Faults()
    c = codec()
    with StepBagWriter(path, storage=storage, pixels=bool(images)) as w:
        for k in range(steps):
            ep, es = divmod(k, EP_LEN + 1)
            stamp = 1_000_000 * (k + 1)
            fb = StepFeedbackFields(
                episode=ep, episode_step=es, first=es == 0, last=es == EP_LEN,
                reward=0.0 if es == 0 else k * 0.5,
                applied_action=np.zeros(0) if es == 0 else np.array([k, -k], np.float32),
                action_status=0 if es == 0 else 1, task='Toy-v0')
            msgs = {
                TOPIC_STATE: c.state(k, stamp, np.array([k, ep], float)),
                TOPIC_STEP: c.feedback(k, stamp, fb),
                TOPIC_CONTEXT_TRUTH: c.truth(k, stamp, ['mass'], np.array([1.0 + ep]), ep),
                TOPIC_ACTION: c.action(k, stamp, np.array([k + 1, -k - 1], np.float32)),
            }
            for topic, msg in msgs.items():
                if (topic, k) in faults.drop:
                    continue
                vector = getattr(msg, VECTORS[topic])
                if (topic, k) in faults.nan:
                    vector[0] = np.nan
                if (topic, k) in faults.short:
                    setattr(msg, VECTORS[topic], vector[:-1])
                if (topic, k) in faults.shift:
                    msg.header.stamp.nanosec += 7
                for _ in range(2 if (topic, k) in faults.dup else 1):
                    w.write_serialized(topic, stamp, c.serialize(msg))
        for stamp, raw in images:
            w.write_serialized(TOPIC_IMAGE, stamp, raw)
    return path


def test_synthetic_bag_ingests_step_aligned(tmp_path: Path) -> None:
    """a_k and r_{k+1} come from StepFeedback k+1; obs, context and stamps from step k."""
    ds = ingest_bags(_write_synthetic(tmp_path / 'bag', 12))
    assert [len(e.steps) for e in ds.episodes] == [6, 6]
    ep = ds.episodes[1]
    np.testing.assert_array_equal(ep.steps, np.arange(6, 12))
    np.testing.assert_array_equal(ep.obs[:, 0], np.arange(6, 12))
    np.testing.assert_array_equal(ep.action[:, 0], np.arange(7, 12))
    np.testing.assert_array_equal(ep.reward, np.arange(7, 12) * 0.5)
    np.testing.assert_array_equal(ep.policy_action[:, 0], np.arange(7, 13))
    np.testing.assert_array_equal(ep.context[:, 0], 2.0)
    np.testing.assert_array_equal(ep.stamps_ns, 1_000_000 * np.arange(7, 13))
    assert ep.first.tolist() == [True] + [False] * 5 and ep.last.tolist() == [False] * 5 + [True]
    assert ds.task == 'Toy-v0' and ds.context_names == ('mass',)
    assert not ds.report.issues


def test_gap_on_one_topic_reported_and_episode_cut(tmp_path: Path) -> None:
    """A state missing at step 3 is reported with file, topic and step; no transition spans it."""
    bag = _write_synthetic(tmp_path / 'gap', 6, Faults(drop={(TOPIC_STATE, 3)}))
    with pytest.warns(IngestWarning, match='step 3'):
        ds = ingest_bags(bag)
    [issue] = ds.report.issues
    assert (issue.file, issue.topic, issue.step, issue.kind) == (str(bag), TOPIC_STATE, 3, 'gap')
    assert [e.steps.tolist() for e in ds.episodes] == [[0, 1, 2], [4, 5]]


def test_gap_on_all_topics_reported(tmp_path: Path) -> None:
    """A step absent on every topic is one gap issue at that step."""
    drop = {(t, 8) for t in (TOPIC_STATE, TOPIC_STEP, TOPIC_CONTEXT_TRUTH, TOPIC_ACTION)}
    with pytest.warns(IngestWarning):
        ds = ingest_bags(_write_synthetic(tmp_path / 'hole', 12, Faults(drop=drop)))
    assert [(i.topic, i.step, i.kind) for i in ds.report.issues] == [(TOPIC_STEP, 8, 'gap')]


def test_duplicate_step_reported(tmp_path: Path) -> None:
    """A step written twice on /zeus/step is reported with file, topic and step, kept once."""
    bag = _write_synthetic(tmp_path / 'dup', 6, Faults(dup={(TOPIC_STEP, 2)}))
    with pytest.warns(IngestWarning, match='duplicate'):
        ds = ingest_bags(bag)
    [issue] = ds.report.issues
    assert (issue.file, issue.topic, issue.step, issue.kind) == (str(bag), TOPIC_STEP, 2,
                                                                 'duplicate')
    assert ds.episodes[0].steps.tolist() == [0, 1, 2, 3, 4, 5]


def test_stamp_mismatch_reported(tmp_path: Path) -> None:
    """A context truth whose stamp differs from its step's is reported and not used."""
    bag = _write_synthetic(tmp_path / 'st', 6, Faults(shift={(TOPIC_CONTEXT_TRUTH, 4)}))
    with pytest.warns(IngestWarning):
        ds = ingest_bags(bag)
    [issue] = ds.report.issues
    assert (issue.topic, issue.step, issue.kind) == (TOPIC_CONTEXT_TRUTH, 4, 'stamp_mismatch')
    assert [e.steps.tolist() for e in ds.episodes] == [[0, 1, 2, 3]]


def test_strict_raises_on_issue(tmp_path: Path) -> None:
    """strict=True turns a reported gap into an IngestError naming file, topic and step."""
    bag = _write_synthetic(tmp_path / 'gap', 6, Faults(drop={(TOPIC_STATE, 3)}))
    with pytest.raises(IngestError, match=rf'{bag}.*{TOPIC_STATE} step 3'):
        ingest_bags(bag, strict=True)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_truncated_bag_named(tmp_path: Path, storage: str) -> None:
    """A bag whose storage file was cut short raises BagError naming that bag."""
    bag = _write_synthetic(tmp_path / 'cut', 60, storage=storage)
    [data] = [p for p in bag.iterdir() if p.suffix in {'.mcap', '.db3'}]
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    with pytest.raises(BagError) as info:
        ingest_bags(bag)
    assert info.value.path == bag


def test_unclosed_bag_named(tmp_path: Path) -> None:
    """A torn bag folder (no metadata.yaml, no mcap footer): the error names zeus recover.

    (A complete mcap without metadata.yaml is another writer's: test_ingest_foreign.py.)
    """
    from test_ingest_foreign import cut_like_a_kill

    from zeus_ros.cli import recover

    bag = _write_synthetic(tmp_path / 'killed', 12)
    (bag / 'metadata.yaml').unlink()
    cut_like_a_kill(bag / 'killed.mcap')
    with pytest.raises(BagError, match=r'no metadata\.yaml') as info:
        ingest_bags(tmp_path)
    assert info.value.path == bag
    text = str(info.value)
    assert 'killed.mcap' in text and f'zeus recover {bag}' in text, text
    assert recover.main([str(bag)]) == 0  # ... which, run as it says, makes it readable
    assert ingest_bags(bag).num_transitions == 10


def test_bag_metadata_is_what_jazzy_writes(tmp_path: Path) -> None:
    """Version 9, ros_distro jazzy (also inside the mcap), offered QoS and RIHS01 per topic."""
    from ruamel.yaml import YAML

    from zeus_ros.bags.schema import MSGTYPES, typestore

    for storage in ('mcap', 'sqlite3'):
        bag = _write_synthetic(tmp_path / storage, 3, storage=storage)
        info = YAML(typ='safe').load((bag / 'metadata.yaml').read_text())[
            'rosbag2_bagfile_information']
        assert (info['version'], info['ros_distro']) == (9, 'jazzy')
        assert len(info['topics_with_message_count']) == 4
        for entry in info['topics_with_message_count']:
            meta = entry['topic_metadata']
            assert meta['type_description_hash'] == typestore().hash_rihs01(
                MSGTYPES[meta['name']])
            [qos] = meta['offered_qos_profiles']
            assert (qos['reliability'], qos['durability']) == ('reliable', 'volatile')
            assert qos['deadline'] == {'sec': 9223372036, 'nsec': 854775807}
        with AnyReader([bag]) as reader:
            assert all(c.ext.offered_qos_profiles[0].depth == 0 for c in reader.connections)
    assert b'ros_distro: jazzy' in (tmp_path / 'mcap' / 'mcap.mcap').read_bytes()


def _renamed(src: Path, dst: Path, namespace: str) -> Path:
    """Copy a bag with every zeus topic moved under /namespace (as `ros2 bag record` sees it)."""
    from rosbags.rosbag2 import Writer

    from zeus_ros.offline.data.ingest import bag_topic

    with AnyReader([src]) as reader, Writer(dst, version=9) as writer:
        conns = {c.id: writer.add_connection(bag_topic(c.topic, namespace), c.msgtype,
                                             typestore=codec().store)
                 for c in reader.connections}
        for conn, log, raw in reader.messages():
            writer.write(conns[conn.id], log, raw)
    return dst


def test_namespaced_bag_needs_its_namespace(tmp_path: Path, capsys: Any) -> None:
    """/r1/zeus/... topics need --namespace r1, and the error says so; with it, same episodes.

    Without it: 'no zeus topics (found these: ...)', never 'corrupt'.
    """
    from zeus_ros.cli.ingest import main

    plain = _write_synthetic(tmp_path / 'plain', 12)
    spaced = _renamed(plain, tmp_path / 'spaced', 'r1')
    with pytest.raises(BagError, match=r'no zeus topics \(found these: /r1/zeus/action, '
                       r'/r1/zeus/context_truth, .*\).*--namespace r1'):
        ingest_bags(spaced)
    ds = ingest_bags(spaced, namespace='/r1/', strict=True)
    assert [e.steps.tolist() for e in ds.episodes] == [
        e.steps.tolist() for e in ingest_bags(plain).episodes]
    assert main([str(spaced), '--namespace', 'r1']) == 0
    assert '10 transitions' in capsys.readouterr().out
    assert main([str(spaced)]) == 1
    assert 'no zeus topics' in capsys.readouterr().err


def test_metadata_count_mismatch_reported(tmp_path: Path) -> None:
    """metadata.yaml listing more /zeus/step messages than the file holds is an issue."""
    bag = _write_synthetic(tmp_path / 'bag', 6)
    meta = bag / 'metadata.yaml'
    text = meta.read_text()
    meta.write_text(text.replace('message_count: 6\n    topic_metadata:\n      name: /zeus/step',
                                 'message_count: 7\n    topic_metadata:\n      name: /zeus/step'))
    assert meta.read_text() != text
    with pytest.warns(IngestWarning, match='lists 7 messages but 6 were read'):
        ds = ingest_bags(bag)
    assert [(i.topic, i.kind) for i in ds.report.issues] == [(TOPIC_STEP, 'count')]


def test_corrupt_bag_skipped_and_counted(tmp_path: Path) -> None:
    """skip_corrupt=True ingests the good bag and lists the corrupt one in the report."""
    _write_synthetic(tmp_path / 'a_good', 12)
    bad = _write_synthetic(tmp_path / 'b_bad', 12)
    [data] = bad.glob('*.mcap')
    data.write_bytes(data.read_bytes()[:100])
    with pytest.warns(IngestWarning, match='b_bad'):
        ds = ingest_bags(tmp_path, skip_corrupt=True)
    assert len(ds.report.skipped) == 1 and ds.report.skipped[0][0] == str(bad)
    assert ds.report.bags == [str(tmp_path / 'a_good')]
    assert ds.num_transitions == 10


def test_single_storage_file_accepted(tmp_path: Path) -> None:
    """A bare .mcap file ingests like its bag directory."""
    bag = _write_synthetic(tmp_path / 'bag', 12)
    [data] = bag.glob('*.mcap')
    assert ingest_bags(data).num_transitions == ingest_bags(bag).num_transitions == 10


def test_interrupted_writer_leaves_readable_bag(tmp_path: Path) -> None:
    """A KeyboardInterrupt inside the writer's with-block still finalizes the bag."""
    with pytest.raises(KeyboardInterrupt), StepBagWriter(tmp_path / 'b2', pixels=False) as w:
        c = codec()
        fb = StepFeedbackFields(episode=0, episode_step=0, first=True, last=False, reward=0.0,
                                applied_action=np.zeros(0), action_status=0, task='Toy-v0')
        w.write_serialized(TOPIC_STEP, 1, c.serialize(c.feedback(0, 1, fb)))
        raise KeyboardInterrupt
    assert w.closed and (tmp_path / 'b2' / 'metadata.yaml').exists()
    with AnyReader([tmp_path / 'b2']) as reader:
        assert reader.message_count == 1


def test_definitions_embedded_for_other_tools(tmp_path: Path) -> None:
    """The rosbags AnyReader decodes our bag from the definitions embedded in it alone."""
    bag = _write_synthetic(tmp_path / 'bag', 3)
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC_STEP]
        msgs: list[Any] = [reader.deserialize(raw, c.msgtype)
                           for c, _, raw in reader.messages(connections=conns)]
    assert [m.task for m in msgs] == ['Toy-v0'] * 3
    assert msgs[2].applied_action.tolist() == [2.0, -2.0]


# --- collect -> ingest round trip on the real ScheduledEnv ---------------------------------

ROUND_TRIP_TASK = 'Cheetah-Run-v1'  # 40-step episodes: 100 steps cross two episode ends


class RecordingEnv:
    """The real ScheduledEnv, keeping every EnvStep it returns as the ground truth."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self.seen: dict[int, Any] = {}

    def reset(self) -> Any:
        """Reset the env and keep the first step."""
        return self._keep(self.env.reset())

    def step(self, action: np.ndarray) -> Any:
        """Step the env and keep the result."""
        return self._keep(self.env.step(action))

    def _keep(self, es: Any) -> Any:
        self.seen[int(es.step)] = es
        return es


def _run_collect(out: Path, *, storage: str, pixels: bool, steps: int) -> tuple[Any, dict, dict]:
    """Collect `steps` steps into `out`; return the env record, actions and frames per step."""
    from sim_bridge.env import ScheduledEnv
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config
    from zeus_ros.offline.rollout import collect, random_policy

    task = make_task(ROUND_TRIP_TASK, seed=3)
    env = RecordingEnv(ScheduledEnv(task, schedule_from_config({'kind': 'constant'}, task, 3)))
    inner = random_policy(task, 3)
    actions: dict[int, np.ndarray] = {}
    frames: dict[int, np.ndarray] = {}

    def policy(es: Any, rec: Any) -> Any:
        out_ = inner(es, rec)
        actions[int(es.step)] = out_.action
        if rec.frame is not None:
            frames[int(es.step)] = rec.frame
        return out_

    try:
        with StepBagWriter(out, storage=storage, pixels=pixels) as writer:
            collect(env, task, policy, writer, steps, progress=False)
    finally:
        task.close()
    return env, actions, frames


def _check_against_env(ds: Any, env: RecordingEnv, actions: dict, frames: dict,
                       steps: int) -> None:
    """Every ingested field equals what the env produced for that step."""
    from zeus_ros.bags.schema import ns_from_sim_time

    covered = sorted(int(s) for ep in ds.episodes for s in ep.steps)
    assert covered == list(range(steps))
    assert ds.task == ROUND_TRIP_TASK and not ds.report.issues
    for ep in ds.episodes:
        truth = [env.seen[int(s)] for s in ep.steps]
        np.testing.assert_array_equal(ep.obs, np.stack([t.observation.state for t in truth]))
        assert ep.stamps_ns.tolist() == [ns_from_sim_time(t.sim_time) for t in truth]
        assert ep.first.tolist() == [t.observation.first for t in truth]
        assert ep.last.tolist() == [t.observation.last for t in truth]
        assert ep.episode_step.tolist() == [t.episode_step for t in truth]
        assert {ep.episode} == {t.episode for t in truth}
        np.testing.assert_array_equal(ep.context, [[t.observation.context[n] for n in
                                                    ds.context_names] for t in truth])
        assert ep.segment.tolist() == [t.segment for t in truth]
        np.testing.assert_array_equal(
            ep.action, np.stack([t.applied_action for t in truth[1:]]).astype(np.float32))
        np.testing.assert_array_equal(ep.reward, [t.observation.reward for t in truth[1:]])
        assert ep.action_status.tolist() == [int(t.status) for t in truth[1:]]
        np.testing.assert_array_equal(ep.policy_action,
                                      np.stack([actions[int(s)] for s in ep.steps]))
        if frames:
            assert ep.frames is not None
            np.testing.assert_array_equal(
                ep.frames, np.stack([frames[int(s)].transpose(2, 0, 1) for s in ep.steps]))


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_collect_ingest_round_trip(tmp_path: Path, storage: str) -> None:
    """Collected bags ingest back to exactly the env's states, actions, rewards and context."""
    import time

    started = time.time_ns()
    env, actions, frames = _run_collect(tmp_path / 'bag', storage=storage, pixels=False,
                                        steps=100)
    ds = ingest_bags(tmp_path / 'bag')
    assert not ds.has_frames
    _check_against_env(ds, env, actions, frames, 100)
    with AnyReader([tmp_path / 'bag']) as reader:  # bag times: sim time from the run's start
        start = reader.start_time
        conns = [c for c in reader.connections if c.topic == TOPIC_STEP]
        logs = [log for _, log, _ in reader.messages(connections=conns)]
    assert started <= start == logs[0] <= time.time_ns()
    assert logs[9] - logs[0] == ds.episodes[0].stamps_ns[9] - ds.episodes[0].stamps_ns[0]


@pytest.mark.slow
def test_collect_ingest_round_trip_pixels(tmp_path: Path) -> None:
    """With pixels, every 84x84 frame comes back channel-first and bit-exact."""
    env, actions, frames = _run_collect(tmp_path / 'bag', storage='mcap', pixels=True, steps=12)
    ds = ingest_bags(tmp_path / 'bag')
    assert ds.has_frames and len(frames) == 12
    _check_against_env(ds, env, actions, frames, 12)


@pytest.mark.slow
def test_batched_ingest_equals_one_by_one_decoding(tmp_path: Path, monkeypatch: Any) -> None:
    """Batches give the episodes and issues of one-by-one decoding: faulty, state, pixel bags.

    (A recorded bag: test_live_system's recording test.)
    """
    from live_fixtures import assert_ingests_as_one_by_one

    faults = Faults(drop={(TOPIC_STATE, 3)}, dup={(TOPIC_STEP, 9)},
                    shift={(TOPIC_ACTION, 12)},
                    nan={(TOPIC_STATE, 15), (TOPIC_STEP, 20), (TOPIC_ACTION, 22),
                         (TOPIC_CONTEXT_TRUTH, 30)},
                    short={(TOPIC_STEP, 25), (TOPIC_ACTION, 27), (TOPIC_STATE, 33)})
    assert_ingests_as_one_by_one([_write_synthetic(tmp_path / 'faults', 60, faults)],
                                 monkeypatch)
    _run_collect(tmp_path / 'state', storage='mcap', pixels=False, steps=300)
    _run_collect(tmp_path / 'pixels', storage='mcap', pixels=True, steps=30)
    assert_ingests_as_one_by_one([tmp_path / 'state'], monkeypatch)
    assert_ingests_as_one_by_one([tmp_path / 'pixels'], monkeypatch)


@pytest.mark.slow
@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_recorded_pixel_bag_ingests_through_raw_bytes_as_decoded(
        tmp_path: Path, storage: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A recorded 84x84 pixel bag's image batches after the first skip decoding, exactly.

    They take FrameStore.add_raw (pixels sliced from the CDR bytes), and the dataset is the
    one-by-one decode's and what the env rendered, frame for frame (issue 51).
    """
    from zeus_ros.offline.data.frames import FrameStore

    from live_fixtures import assert_ingests_as_one_by_one

    steps = 150
    env, actions, frames = _run_collect(tmp_path / 'bag', storage=storage, pixels=True,
                                        steps=steps)
    calls: list[bool] = []
    add_raw = FrameStore.add_raw
    with monkeypatch.context() as patch:
        patch.setattr(FrameStore, 'add_raw',
                      lambda store, raws: calls.append(add_raw(store, raws)) or calls[-1])
        ds = ingest_bags(tmp_path / 'bag')
    assert calls == [False, True, True], calls  # the first batch is decoded: the model
    _check_against_env(ds, env, actions, frames, steps)
    assert_ingests_as_one_by_one([tmp_path / 'bag'], monkeypatch)


def _frame(k: int, shape: tuple[int, int] = (8, 6)) -> np.ndarray:
    """A distinct HxWx3 uint8 frame per k."""
    return np.random.default_rng(k).integers(0, 256, (*shape, 3), np.uint8)


def test_image_batches_decode_as_rosbags_does() -> None:
    """Images decode in batches to rosbags' fields; pixels stay views of the raw bytes."""
    from zeus_ros.bags.cdr_columns import decode_messages

    cdc, msgtype = codec(), 'sensor_msgs/msg/Image'
    msgs = [cdc.image(1_000_000_000 * k + 7 * k, _frame(k, (8, 6) if k % 5 else (6, 8)))
            for k in range(40)]
    msgs.append(cdc.image(5, np.zeros((0, 0, 3), np.uint8)))  # no pixels at all
    for k in (7, 8):  # another frame_id shifts every later field
        msgs[k].header.frame_id = 'camera_optical'
    raws = [cdc.serialize(m) for m in msgs]
    raws.append(bytes(cdc.store.serialize_cdr(msgs[1], msgtype, little_endian=False)))
    slow: list[int] = []

    def one(i: int) -> Any:
        slow.append(i)
        return cdc.deserialize(raws[i], msgtype)

    decoded = decode_messages(raws, msgtype, one)
    for i, (raw, ours) in enumerate(zip(raws, decoded, strict=True)):
        theirs = cdc.deserialize(raw, msgtype)
        assert ours.stamp_ns == theirs.header.stamp.sec * 10**9 + theirs.header.stamp.nanosec
        for name in ('height', 'width', 'encoding', 'is_bigendian', 'step'):
            mine, ref = getattr(ours, name), getattr(theirs, name)
            assert type(mine) is type(ref) and mine == ref, name
        assert ours.data.dtype == np.uint8 and np.array_equal(ours.data, theirs.data)
        if i not in slow:
            assert ours.data.base is raw  # no copy of the pixels
    assert len(raws) - 1 in slow and len(slow) < 8, slow


def test_pixel_frames_exact_in_any_image_order(tmp_path: Path) -> None:
    """Frames come back channel-first and exact: images in order, reversed, or of odd shape.

    Episode 0's images are in step order, episode 1's reversed, and step 15 has a 6x8 image
    before its 8x6 one (a duplicate; the first is used, read with the episode's 8x6 shape).
    """
    stamp = {k: 1_000_000 * (k + 1) for k in range(18)}
    odd = _frame(99, (6, 8))
    order = [*range(6), *reversed(range(6, 12)), *range(12, 18)]
    images = [(stamp[k], codec().serialize(codec().image(stamp[k], _frame(k)))) for k in order]
    images.insert(15, (stamp[15], codec().serialize(codec().image(stamp[15], odd))))
    with pytest.warns(IngestWarning, match='2 images with stamp'):
        ds = ingest_bags(_write_synthetic(tmp_path / 'pix', 18, images=images))
    assert [(i.topic, i.step, i.kind) for i in ds.report.issues] == [(TOPIC_IMAGE, 15,
                                                                     'duplicate')]
    assert ds.has_frames and [e.steps.tolist() for e in ds.episodes] == [
        list(range(0, 6)), list(range(6, 12)), list(range(12, 18))]
    for ep in ds.episodes:
        expected = [_frame(k) if k != 15 else odd.reshape(8, 6, 3) for k in ep.steps]
        assert ep.frames is not None and ep.frames.flags.c_contiguous
        assert ep.frames.dtype == np.uint8 and ep.frames.shape == (6, 3, 8, 6)
        np.testing.assert_array_equal(ep.frames, np.stack([f.transpose(2, 0, 1)
                                                           for f in expected]))


def test_frame_store_grows_past_what_the_metadata_lists() -> None:
    """More images than the bag's metadata lists: the store grows, no frame is lost."""
    from zeus_ros.offline.data.frames import FrameStore

    frames = [_frame(k) for k in range(5)]
    store = FrameStore(listed=1, bag_bytes=10**9)
    rows = store.add([SimpleNamespace(height=8, width=6, data=f.reshape(-1), stamp_ns=k)
                      for k, f in enumerate(frames)])
    assert rows == list(range(5)) and store.read == 5
    np.testing.assert_array_equal(store.stack(rows), np.stack([f.transpose(2, 0, 1)
                                                               for f in frames]))


def test_frame_store_grows_from_raw_bytes_too() -> None:
    """add_raw, past what the metadata lists, grows the store too; other stamps come out right."""
    from zeus_ros.bags.cdr_columns import decode_messages
    from zeus_ros.offline.data.frames import FrameStore

    cdc, msgtype = codec(), 'sensor_msgs/msg/Image'
    frames = [_frame(k) for k in range(40)]
    stamps = [3_000_000_000 * k + 7 * k for k in range(40)]
    raws = [cdc.serialize(cdc.image(stamp, f)) for stamp, f in zip(stamps, frames, strict=True)]
    store = FrameStore(listed=2, bag_bytes=10**9)
    assert not store.add_raw(raws[:4])  # nothing decoded yet: no model
    store.add(decode_messages(raws[:4], msgtype, lambda i: cdc.deserialize(raws[i], msgtype)),
              raws[:4])
    assert store.add_raw(raws[4:20]) and store.add_raw(raws[20:])
    assert store.stamps == stamps and store.refs == list(range(40)) and store.count == 40
    assert store.rows is not None and len(store.rows) == 64
    np.testing.assert_array_equal(store.stack(store.refs),
                                  np.stack([f.transpose(2, 0, 1) for f in frames]))
    assert not store.add_raw([cdc.serialize(cdc.image(5, _frame(0, (6, 8))))])  # another shape
    assert store.read == 40


def test_image_batches_stored_from_raw_bytes_as_decoded(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """Batches of images alike but for stamp and pixels skip decoding, with the same result.

    1100 steps (stamps past one second), so most batches take FrameStore.add_raw; the first
    (no model yet), one with another frame_id and one with an image of another shape are
    decoded. One image repeats a stamp (a duplicate, reported as when decoded).
    """
    from zeus_ros.offline.data.frames import FrameStore

    from live_fixtures import assert_ingests_as_one_by_one

    steps = 1100
    cdc = codec()
    frames = {k: _frame(k) for k in range(steps)}
    frames[700] = _frame(700, (6, 8))
    msgs = {k: cdc.image(1_000_000 * (k + 1), frames[k]) for k in range(steps)}
    msgs[300].header.frame_id = 'camera_optical'
    order = [*range(0, 500), *reversed(range(500, 900)), *range(900, steps)]
    images = [(1_000_000 * (k + 1), cdc.serialize(msgs[k])) for k in order]
    images.insert(1001, (images[1000][0], cdc.serialize(cdc.image(images[1000][0], _frame(0)))))
    bag = _write_synthetic(tmp_path / 'many', steps, images=images)
    calls: list[bool] = []
    add_raw = FrameStore.add_raw
    monkeypatch.setattr(FrameStore, 'add_raw',
                        lambda store, raws: calls.append(add_raw(store, raws)) or calls[-1])
    with pytest.warns(IngestWarning, match='2 images with stamp'):
        ds = ingest_bags(bag)
    monkeypatch.undo()
    assert len(calls) == 18 and calls.count(False) == 3, calls
    assert ds.has_frames and ds.report.steps == steps
    for ep in ds.episodes:
        assert ep.frames is not None and ep.frames.dtype == np.uint8
        assert ep.frames.flags.c_contiguous and ep.frames.shape == (len(ep.steps), 3, 8, 6)
        np.testing.assert_array_equal(ep.frames, np.stack([
            frames[int(k)].reshape(8, 6, 3).transpose(2, 0, 1) for k in ep.steps]))
    assert_ingests_as_one_by_one([bag], monkeypatch)


def test_pieces_split_as_step_by_step() -> None:
    """Episode pieces (vectorised) split where the step-by-step rule of before splits them.

    A new piece starts at a hole, an episode start, after a last step, at another episode,
    before a cut step, and where episode_step skips (reported as an 'episode' issue).
    """
    from zeus_ros.offline.data.ingest import IngestReport, Issue, _pieces

    def reference(steps: list[int], fb: dict, cut: set[int]) -> tuple[list, list]:
        pieces: list[list[int]] = []
        issues = []
        prev = None
        for step in steps:
            msg = fb[step][1]
            cont = (prev is not None and step == prev + 1 and not msg.first
                    and step not in cut and not fb[prev][1].last
                    and msg.episode == fb[prev][1].episode)
            if cont and msg.episode_step != fb[prev][1].episode_step + 1:
                issues.append(Issue('bag', TOPIC_STEP, step, 'episode',
                                    f'episode_step {msg.episode_step} does not follow '
                                    f'{fb[prev][1].episode_step}'))
                cont = False
            if cont:
                pieces[-1].append(step)
            else:
                pieces.append([step])
            prev = step
        return [p for p in pieces if len(p) >= 2], issues

    rng = np.random.default_rng(0)
    reported = 0
    for trial in range(30):
        fb, episode, episode_step = {}, 0, 0
        for step in range(200):
            first = rng.random() < 0.05
            episode, episode_step = (episode + 1, 0) if first else (
                episode + (rng.random() < 0.02), episode_step + 1 + (rng.random() < 0.03))
            fb[step] = (step, SimpleNamespace(first=first, last=rng.random() < 0.04,
                                              episode=episode, episode_step=episode_step))
        steps = sorted(int(s) for s in rng.choice(200, 180 - trial, replace=False))
        cut = {int(s) for s in rng.choice(200, trial % 7, replace=False)}
        report = IngestReport()
        assert _pieces(Path('bag'), steps, fb, report, cut) == reference(steps, fb, cut)[0]
        assert report.issues == reference(steps, fb, cut)[1]
        reported += len(report.issues)
    assert reported > 30
    assert _pieces(Path('bag'), [], {}, IngestReport()) == []


def test_corrupt_image_names_the_bag(tmp_path: Path) -> None:
    """A truncated image message is refused as corruption of its bag, as any bad message."""
    images = [(1_000_000 * (k + 1), codec().serialize(codec().image(1_000_000 * (k + 1),
                                                                  _frame(k))))
              for k in range(12)]
    images[4] = (images[4][0], images[4][1][:-40])
    bag = _write_synthetic(tmp_path / 'bad_image', 12, images=images)
    with pytest.raises(BagError, match='corrupt or truncated') as info:
        ingest_bags(bag)
    assert info.value.path == bag
    # named by its read index: steps 0-3 (5 messages each) and step 4's 4 others came first
    assert 'after 24 messages' in str(info.value)


def test_collect_cli_appends_only_when_asked(tmp_path: Path) -> None:
    """A second `zeus collect` into the same --out needs --append and adds bag_001."""
    from zeus_ros.cli.collect import main

    argv = ['--task', ROUND_TRIP_TASK, '--steps', '30', '--out', str(tmp_path),
            '--no-progress']
    assert main(argv) == 0
    assert main(argv) == 2
    assert main([*argv, '--append', '--seed', '1', '--storage', 'sqlite3']) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag_000', 'bag_001']
    ds = ingest_bags(tmp_path)
    assert len(ds.report.bags) == 2 and ds.report.steps == 60


def test_inline_schedule_form_builds_a_valid_schedule() -> None:
    """The documented inline forms of --schedule give configs the schedule code accepts."""
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config
    from zeus_ros.offline.rollout import parse_schedule

    task = make_task('Cheetah-Run-v0')
    for text in ('constant', 'constant:value=0.8', 'switch:train:every=100',
                 'switch:extrapolation:every_episodes=1,order=sample',
                 'drift:shape=sinusoid,low=0.6,high=1.2,period=500',
                 'random_walk:low=0.4,high=1.4,step_size=0.02'):
        schedule_from_config(parse_schedule(text), task, 0).value_at(250, 1)
    assert parse_schedule('switch:train:every=100') == {
        'kind': 'switch', 'values': 'train', 'every': 100}


@pytest.mark.slow
def test_zeus_train_reads_a_namespaced_bag_with_namespace(tmp_path: Path, capsys: Any) -> None:
    """`zeus train --namespace r1` trains on /r1/zeus/... topics; without it, the error says so."""
    from zeus_ros.cli.collect import main as collect
    from zeus_ros.cli.train import main as train

    assert collect(['--task', ROUND_TRIP_TASK, '--steps', '200', '--out', str(tmp_path / 'c'),
                    '--no-progress']) == 0
    spaced = _renamed(tmp_path / 'c' / 'bag_000', tmp_path / 'spaced', 'r1')
    config = Path(__file__).resolve().parents[1] / 'params' / 'train' / 'state_cpu.yaml'
    argv = ['--bags', str(spaced), '--config', str(config), '--updates', '1', '--no-eval',
            '--no-progress']
    assert train([*argv, '--out', str(tmp_path / 'run0')]) == 2
    assert '--namespace r1' in capsys.readouterr().err
    assert train([*argv, '--out', str(tmp_path / 'run1'), '--namespace', 'r1']) == 0
    assert (tmp_path / 'run1' / 'final.pt').is_file()


def test_bags_are_found_at_any_depth_as_the_recorder_nests_them(tmp_path: Path,
                                                                 capsys: Any) -> None:
    """`zeus launch --record` writes bags/zeus_<date>/zeus_<date>_000/: `--bags bags` finds it.

    Every bag below the folder is found (split bags, sqlite3, deeper), a bag folder is taken
    whole, hidden folders are skipped; ingest, train and recover share this one search. A
    folder without bags is one error naming where it searched and what a bag is.
    """
    from zeus_ros.bags.recording import find_bags
    from zeus_ros.cli.ingest import main as ingest_main
    from zeus_ros.cli.recover import main as recover_main
    from zeus_ros.cli.train import main as train_main

    bags = tmp_path / 'bags'
    run = bags / 'zeus_20260101_120000'
    first = _write_synthetic(run / 'zeus_20260101_120000_000', 12)
    split = _write_synthetic(run / 'zeus_20260101_120000_001', 12)
    deeper = _write_synthetic(bags / 'robot1' / 'day2' / 'run', 12, storage='sqlite3')
    _write_synthetic(first / 'not_searched_inside_a_bag', 12)
    _write_synthetic(bags / '.trash' / 'old', 12)
    assert find_bags(bags) == [deeper, first, split]
    assert find_bags([run, deeper / 'run.db3']) == [first, split, deeper / 'run.db3']
    assert ingest_main(['--bags', str(bags)]) == 0
    assert 'Toy-v0: 6 episode piece(s), 30 transitions' in capsys.readouterr().out
    assert recover_main([str(bags), '--dry-run']) == 0
    assert capsys.readouterr().out.count('closed properly, nothing to recover') == 3

    empty = tmp_path / 'nothing' / 'here'
    empty.mkdir(parents=True)
    (empty / 'notes.txt').write_text('no bag')
    assert ingest_main(['--bags', str(tmp_path / 'nothing')]) == 1
    error = capsys.readouterr().err.strip()
    assert error == (f'zeus ingest: {tmp_path / "nothing"}: no bags found: searched '
                     f'{(tmp_path / "nothing").resolve()} and every folder below it for '
                     'rosbag2 bags: folders with metadata.yaml, or .mcap / .db3 files'), error
    from tiny_config import TINY, write_config

    config = write_config(tmp_path / 'tiny.yaml', TINY)
    assert train_main(['--bags', str(tmp_path / 'nothing'), '--config', str(config), '--out',
                       str(tmp_path / 'run'), '--no-progress']) == 2
    assert 'no bags found: searched' in capsys.readouterr().err


def test_a_short_first_state_is_the_one_blamed_not_the_good_ones(tmp_path: Path) -> None:
    """The length most messages have sets the state size: step 0 is reported, 1.. are kept."""
    bag = _write_synthetic(tmp_path / 'short0', 30, Faults(short={(TOPIC_STATE, 0)}))
    with pytest.warns(IngestWarning):
        ds = ingest_bags(bag)
    [issue] = [i for i in ds.report.issues if i.kind == 'length']
    assert (issue.topic, issue.step) == (TOPIC_STATE, 0)
    assert '1 message(s) of another length than the 2 of most' in issue.detail
    assert ds.num_transitions > 20 and all(ep.obs.shape[1] == 2 for ep in ds.episodes)


def test_a_truncated_bag_points_at_zeus_recover(tmp_path: Path) -> None:
    """Cut short: the error says what `zeus recover` would do, with the bag's path."""
    bag = _write_synthetic(tmp_path / 'cut', 60)
    [data] = list(bag.glob('*.mcap'))
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    with pytest.raises(BagError, match=r'cannot open bag|corrupt or truncated') as info:
        ingest_bags(bag)
    assert f'`zeus recover {bag}` restores what was written' in str(info.value)


def test_a_type_hash_mismatch_is_named_as_such_when_decoding_fails(tmp_path: Path) -> None:
    """A message of another definition is not called corrupt: the error names the hashes."""
    from zeus_ros.offline.data.ingest import IngestReport, read_failure

    bag = tmp_path / 'other_definition'
    report = IngestReport()
    report.issues.append(Issue(str(bag), TOPIC_STATE, None, 'schema',
                               "type hash RIHS01_aa != this checkout's RIHS01_bb for "
                               'zeus_msgs/msg/StateVector: written with another definition; '
                               'decoding may fail'))
    error = read_failure(bag, 12, ValueError('buffer too short'), report)
    text = str(error)
    assert 'written with another message definition' in text and 'RIHS01_aa' in text
    assert 'corrupt' not in text and 'zeus recover' not in text
