"""Rebuild step-aligned episodes from zeus bags (the only way training sees data).

Messages are joined by their `step` index (images, which carry no step, by header stamp).
Transition k of an episode is (o_k, a_k, r_{k+1}, o_{k+1}) where a_k is the `applied_action`
of StepFeedback k+1 (what the physics saw, after clipping or a timeout's safe action) and
r_{k+1} its reward. A step missing from any required topic cuts its episode there: the pieces
on either side become separate episodes, so no transition or history spans a hole.

A bag recorded with `ros2 bag record` from a namespaced system holds /<ns>/zeus/... topics:
ingest it with `namespace=` (`zeus ingest --namespace <ns>`). What metadata.yaml counts and what
was read must agree; a difference is reported like a gap.

Every numeric field is checked: a value that is NaN, infinite or beyond MAX_ABS, or a vector
whose length differs from the one most messages of that topic have, makes its data
unusable. A bad state or context drops its step (both transitions touching it); a bad reward or
applied action in StepFeedback k+1 drops transition k only. Either way the episode is cut there,
so no history contains the bad value. Each (topic, field) is reported once with its count and
first steps; `strict` refuses the bag instead.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from contextlib import suppress
from dataclasses import dataclass, field
import gc
from itertools import compress
from operator import attrgetter, itemgetter
from pathlib import Path
import re
import struct
import time
from typing import TYPE_CHECKING, Any
import warnings

import numpy as np
from rosbags.rosbag2 import Reader

from zeus_ros.bags.cdr_columns import decode_messages, stack_field
from zeus_ros.bags.errors import BagError, IngestError
from zeus_ros.bags.mcap_file import channel_qos, closed_by_writer, qos_text
from zeus_ros.bags.recording import find_bags
from zeus_ros.bags.schema import (
    MSGTYPES,
    TOPIC_ACTION,
    TOPIC_CONTEXT_TRUTH,
    TOPIC_IMAGE,
    TOPIC_STATE,
    TOPIC_STEP,
    codec,
)
from zeus_ros.offline.data.frames import FrameStore

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator, Sequence

__all__ = ['Dataset', 'Episode', 'IngestReport', 'IngestWarning', 'Issue',
           'bag_topic', 'ingest_bags']

_STEP_TOPICS = (TOPIC_STATE, TOPIC_STEP, TOPIC_CONTEXT_TRUTH, TOPIC_ACTION)
_READ_TOPICS = (*_STEP_TOPICS, TOPIC_IMAGE)
_MAX_LISTED = 20
_IMAGE_BATCH = 64
"""Images decoded at once: enough to batch, few enough that their bytes stay in cache."""
_FIRST_STEPS = 5
_STAMP, _MESSAGE = itemgetter(0), itemgetter(1)
MAX_ABS = 1e9
"""Largest magnitude accepted in a float field: beyond it a value is no more usable than Inf
(no simulator state, reward or applied action comes near; float32 loses the units digit)."""


class IngestWarning(UserWarning):
    """Bags were read but hold gaps, duplicates or mismatched stamps."""


@dataclass(frozen=True)
class Issue:
    """One inconsistency found in a bag: where (file, topic, step) and what."""

    file: str
    topic: str
    step: int | None
    kind: str
    """gap | duplicate | stamp_mismatch | episode | schema | count | nonfinite | length."""
    detail: str

    def __str__(self) -> str:
        where = f'step {self.step}' if self.step is not None else 'no step'
        return f'{self.file}: {self.topic} {where}: {self.kind}: {self.detail}'


@dataclass
class IngestReport:
    """What ingest read, skipped and found wrong, and how fast."""

    bags: list[str] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)
    """(bag, reason) of corrupt bags skipped with skip_corrupt=True."""
    issues: list[Issue] = field(default_factory=list)
    file_bytes: int = 0
    messages: int = 0
    steps: int = 0
    seconds: float = 0.0
    dropped: int = 0
    """Transitions dropped for non-finite or wrong-length values (histories cut there too)."""

    @property
    def mb_per_s(self) -> float:
        """Bag bytes on disk ingested per second (MB = 1e6 bytes)."""
        return self.file_bytes / 1e6 / max(self.seconds, 1e-9)

    @property
    def steps_per_s(self) -> float:
        """Control steps ingested per second."""
        return self.steps / max(self.seconds, 1e-9)

    def summary(self) -> str:
        """One line for logs and the CLI."""
        return (
            f'{len(self.bags)} bag(s), {self.steps} steps, {self.messages} messages, '
            f'{self.file_bytes / 1e6:.1f} MB in {self.seconds:.2f} s '
            f'({self.mb_per_s:.1f} MB/s, {self.steps_per_s:.0f} steps/s); '
            f'{len(self.issues)} issue(s), {len(self.skipped)} corrupt bag(s) skipped'
            + (f', {self.dropped} transition(s) dropped for bad values' if self.dropped else '')
        )


@dataclass
class Episode:
    """A contiguous run of steps of one episode: T transitions over T+1 observations."""

    source: str
    """The bag it came from."""
    episode: int
    steps: np.ndarray
    """(T+1,) int64 global step indices, consecutive."""
    stamps_ns: np.ndarray
    """(T+1,) int64 header stamps (simulation time)."""
    obs: np.ndarray
    """(T+1, D) float64 state observations."""
    frames: np.ndarray | None
    """(T+1, 3, H, W) uint8 channel-first RGB frames, or None without pixels."""
    action: np.ndarray
    """(T, A) float32: a_k as applied by the simulator (from StepFeedback k+1)."""
    action_status: np.ndarray
    """(T,) uint8 StepFeedback.action_status of a_k."""
    policy_action: np.ndarray
    """(T+1, A) float32: what the policy asked for at each step (/zeus/action); NaN if absent."""
    reward: np.ndarray
    """(T,) float64: r_{k+1}, earned by a_k."""
    first: np.ndarray
    """(T+1,) bool."""
    last: np.ndarray
    """(T+1,) bool: True at a time-limit end (which bootstraps: no terminal states here)."""
    episode_step: np.ndarray
    """(T+1,) int64."""
    context: np.ndarray
    """(T+1, C) float64 true context per step."""
    segment: np.ndarray
    """(T+1,) int64 context segment counter."""

    @property
    def num_transitions(self) -> int:
        """T, the number of (o_k, a_k, r_{k+1}, o_{k+1}) transitions."""
        return int(self.action.shape[0])


@dataclass
class Dataset:
    """Episodes of one task, with the names needed to interpret them."""

    task: str
    context_names: tuple[str, ...]
    episodes: list[Episode]
    report: IngestReport

    @property
    def num_transitions(self) -> int:
        """Transitions over all episodes."""
        return sum(ep.num_transitions for ep in self.episodes)

    @property
    def has_frames(self) -> bool:
        """True when every episode carries pixel frames."""
        return bool(self.episodes) and all(ep.frames is not None for ep in self.episodes)

    @property
    def obs_dim(self) -> int:
        """Length of the state observation."""
        return int(self.episodes[0].obs.shape[1])

    @property
    def action_dim(self) -> int:
        """Number of actuators."""
        return int(self.episodes[0].action.shape[1])


def bag_topic(topic: str, namespace: str = '') -> str:
    """The name a schema topic has in a bag of a system in `namespace` (/clock stays global)."""
    ns = namespace.strip('/')
    return f'/{ns}{topic}' if ns and topic.startswith('/zeus/') else topic


def _without_metadata(path: Path) -> BagError:
    """A bag folder without metadata.yaml and no complete mcap: torn; say what `zeus recover` does.

    (A complete mcap without metadata.yaml, closed by another writer, is read as it is.)
    """
    files = sorted(path.glob('*.mcap')) + sorted(path.glob('*.db3'))
    inside = ', '.join(f.name for f in files) or 'no .mcap or .db3 file'
    return BagError(path, f'no metadata.yaml in this bag folder and no complete file (a mcap '
                          f'without its footer: the recorder was killed or its disk filled); it '
                          f'holds {inside}. Run `zeus recover {path}` to close it')


def _no_zeus_topics(path: Path, topics: list[str], namespace: str) -> BagError:
    """No schema topic in the bag: list what it holds and hint at a namespace."""
    where = f' in namespace /{namespace.strip("/")}' if namespace.strip('/') else ''
    hint = ''
    spaces = sorted({m.group(1) for t in topics if (m := re.fullmatch(r'/(.+)/zeus/step', t))})
    if spaces:
        hint = (f'; a namespaced system? pass --namespace {spaces[0]} (ingest_bags(..., '
                f'namespace={spaces[0]!r}))')
    return BagError(path, f'no zeus topics{where} (found these: '
                          f'{", ".join(sorted(topics)) or "none"}){hint}')


@dataclass
class _Topic:
    """Per-topic columns of one bag: step -> (stamp, message), first occurrence wins."""

    by_step: dict[int, tuple[int, Any]] = field(default_factory=dict)


def _read_bag(path: Path, report: IngestReport, namespace: str = '') -> dict[str, Any]:
    """Deserialize the zeus topics of one bag, reporting duplicates; raise BagError if broken."""
    cdc = codec()
    topics: dict[str, _Topic] = {t: _Topic() for t in _STEP_TOPICS}
    reader = _open_reader(path, report)
    count = 0
    raws: dict[str, list[bytes]] = {t: [] for t in _READ_TOPICS}
    frames: FrameStore | None = None
    schema_topic = {bag_topic(t, namespace): t for t in _READ_TOPICS}
    read: Counter[str] = Counter()
    try:
        conns = [c for c in reader.connections if c.topic in schema_topic]
        if not conns:  # an empty filter would read every topic of the bag
            raise _no_zeus_topics(path, sorted({c.topic for c in reader.connections}),
                                  namespace)
        for conn in conns:
            expected = MSGTYPES[schema_topic[conn.topic]]
            if conn.msgtype != expected:
                raise BagError(path, f'topic {conn.topic} has type {conn.msgtype}, '
                                     f'expected {expected}')
            ours = cdc.store.hash_rihs01(expected)
            if conn.digest.startswith('RIHS01_') and conn.digest != ours:
                report.issues.append(Issue(str(path), conn.topic, None, 'schema',
                                           f"type hash {conn.digest} != this checkout's "
                                           f'{ours} for {expected}: written with another '
                                           'definition; decoding may fail'))
        # Messages are decoded in batches (cdr_columns), not one by one: the step topics after
        # the read, images every _IMAGE_BATCH messages, their pixels copied into `frames` so
        # that the raw messages can go. Only raw bytes are kept, no read index each: a corrupt
        # message's is found again (_Place).
        keep = {c.id: raws[schema_topic[c.topic]].append for c in conns}
        pending = raws[TOPIC_IMAGE]
        frames = FrameStore(sum(int(c.msgcount) for c in conns
                                if schema_topic[c.topic] == TOPIC_IMAGE),
                            sum(f.stat().st_size for f in _bag_files(path)))
        place = _Place(path, conns, schema_topic, report)
        for conn, _, raw in reader.messages(connections=conns):
            keep[conn.id](raw)
            if len(pending) == _IMAGE_BATCH:
                _store_images(place, pending, frames)
        _store_images(place, pending, frames)
        for conn in conns:  # one bag topic per schema topic
            topic = schema_topic[conn.topic]
            read[conn.topic] = frames.read if topic == TOPIC_IMAGE else len(raws[topic])
        count = frames.read + sum(len(raws[topic]) for topic in _STEP_TOPICS)
        for topic in _STEP_TOPICS:
            _decode_topic(place, topic, raws[topic], topics[topic].by_step, report, namespace)
    except BagError:
        raise
    except Exception as exc:  # truncated chunk, sqlite errors: named after what was read
        count = (frames.read if frames else 0) + sum(map(len, raws.values()))
        raise read_failure(path, count, exc, report) from exc
    finally:
        reader.close()
    report.messages += count
    _check_counts(path, conns, read, report)
    return {'topics': topics, 'frames': frames}


def _open_reader(path: Path, report: IngestReport) -> Reader:
    """The bag's reader; the .mcap file itself where metadata.yaml cannot describe it.

    A folder without metadata.yaml whose mcap its writer closed (another tool's recording) is
    read as it is, not called cut short; one whose mcap has no footer is torn (`zeus recover`).
    Where metadata.yaml and the file disagree on a topic's QoS, rosbags would leave that
    topic's messages unread: the mismatch is reported (an issue, refused with --strict) and
    the file is read with its own channels.
    """
    mcaps = sorted(path.glob('*.mcap')) if path.is_dir() else []
    source = path
    if path.is_dir() and not (path / 'metadata.yaml').exists():
        if len(mcaps) != 1 or not closed_by_writer(mcaps[0]):
            raise _without_metadata(path)
        source = mcaps[0]  # complete, closed by a writer that writes no metadata.yaml
    try:
        reader = Reader(source)
        reader.open()
    except Exception as exc:  # rosbags raises ReaderError, FileNotFoundError, yaml errors
        raise BagError(path, f'cannot open bag (corrupt or not closed properly?): {exc}; if a '
                             f'crash cut it short, `zeus recover {path}` restores what was '
                             'written') from exc
    if source is path and len(mcaps) == 1 and _qos_mismatches(path, mcaps[0], reader, report):
        reader.close()
        reader = Reader(mcaps[0])
        reader.open()
    return reader


def _qos_mismatches(path: Path, mcap: Path, reader: Reader, report: IngestReport) -> bool:
    """Report each topic whose QoS in metadata.yaml differs from its channel's in the file."""
    try:
        in_file = _file_qos(reader, mcap)
    except (OSError, ValueError, struct.error):  # a torn file: the read names it
        return False
    found = False
    for conn in reader.connections:
        listed = qos_text(list(conn.ext.offered_qos_profiles))
        recorded = qos_text(in_file.get(conn.topic, []))
        if conn.topic in in_file and listed != recorded:
            found = True
            report.issues.append(Issue(
                str(path), conn.topic, None, 'qos',
                f'metadata.yaml offers QoS {listed} but the file recorded {recorded}; rosbags '
                f'pairs them by QoS and would read none of its messages: read from {mcap.name} '
                'itself (fix or regenerate metadata.yaml to silence this)'))
    return found


def _file_qos(reader: Reader, mcap: Path) -> dict[str, list[Any]]:
    """Topic -> QoS profiles of its first channel in `mcap`, as the open `reader` parsed them.

    Why: parsing the channels' QoS again (mcap_file.channel_qos: YAML per channel) cost a
    pixel bag's ingest ~7 % of its time. A reader that does not expose its storages (another
    rosbags version) falls back to that parse.
    """
    storages = getattr(getattr(reader, 'storage', None), 'storages', None) or ()
    for storage in storages:
        if getattr(storage, 'path', None) == mcap:
            found: dict[str, list[Any]] = {}
            for conn in storage.connections:
                found.setdefault(conn.topic, list(conn.ext.offered_qos_profiles))
            return found
    return channel_qos(mcap)


def read_failure(path: Path, count: int | None, exc: Exception, report: IngestReport | None,
                 topic: str = '') -> BagError:
    """Why a bag could not be read to its end, named as precisely as the bag allows.

    A message written with another definition (its type hash differs from this checkout's)
    fails to decode like a torn file does; it is named as such, since `zeus recover` cannot help
    it. Otherwise the file is corrupt or cut short, and `zeus recover` rebuilds what was written.
    """
    where = f'after {count} messages' if count is not None else f'in a {topic} message'
    schema = [i for i in (report.issues if report else ())
              if i.kind == 'schema' and i.file == str(path)]
    if schema:
        return BagError(path, f'cannot decode {where}: written with another message definition '
                              f'({schema[0].detail.split(": written")[0]}); read it with the '
                              f'zeus_ros version that wrote it, or re-record ({exc})')
    return BagError(path, f'corrupt or truncated {where}: {exc}; if a crash cut it short, '
                          f'`zeus recover {path}` restores what was written')


@dataclass
class _Place:
    """Where a bag's messages were read from: names a corrupt one by its read index.

    Why: keeping each message's read index cost more than finding it again, by reading the
    bag's zeus topics up to that message, the one time a message turns out corrupt.
    """

    path: Path
    conns: list[Any]
    schema_topic: dict[str, str]
    report: IngestReport | None = None

    def error(self, topic: str, nth: int, exc: Exception) -> BagError:
        """The BagError of the `nth` message of schema `topic` (0-based), which failed."""
        ids = {c.id for c in self.conns if self.schema_topic[c.topic] == topic}
        seen = 0
        with suppress(Exception), Reader(self.path) as reader:  # else: no index, same error
            for count, (conn, _, _) in enumerate(reader.messages(connections=self.conns)):
                if conn.id in ids and (seen := seen + 1) > nth:
                    return read_failure(self.path, count, exc, self.report)
        return read_failure(self.path, None, exc, self.report, topic)


def _decode(place: _Place, topic: str, raws: list[bytes], before: int = 0) -> list[Any]:
    """Decode one topic's messages in batches (`before` read earlier); a bad one: BagError."""
    cdc = codec()

    def one(i: int) -> Any:
        try:
            return cdc.deserialize(raws[i], MSGTYPES[topic])
        except Exception as exc:  # bad CDR: named like a truncated read
            raise place.error(topic, before + i, exc) from exc

    return decode_messages(raws, MSGTYPES[topic], one)


def _store_images(place: _Place, raws: list[bytes], frames: FrameStore) -> None:
    """Store a batch of images in `frames` (decoded only if it must be); empty `raws`."""
    if not frames.add_raw(raws):
        frames.add(_decode(place, TOPIC_IMAGE, raws, frames.read), raws)
    raws.clear()


def _decode_topic(place: _Place, topic: str, raws: list[bytes],
                  col: dict[int, tuple[int, Any]], report: IngestReport, namespace: str) -> None:
    """Decode one step topic's messages in batches into `col` by step."""
    path = place.path
    messages = _decode(place, topic, raws)
    steps = list(map(int, map(attrgetter('step'), messages)))
    if not col and len(set(steps)) == len(steps):  # the usual bag: each step once
        col.update(zip(steps, zip(map(attrgetter('stamp_ns'), messages), messages,
                                  strict=True), strict=True))
        return
    for step, msg in zip(steps, messages, strict=True):
        if step in col:
            report.issues.append(Issue(str(path), bag_topic(topic, namespace), step,
                                       'duplicate', 'step seen again; keeping the first '
                                       'message'))
        else:
            col[step] = (msg.stamp_ns, msg)


def _check_counts(path: Path, conns: list[Any], read: Counter[str],
                  report: IngestReport) -> None:
    """Report each topic whose message count in the bag's metadata differs from what was read."""
    listed: Counter[str] = Counter()
    for conn in conns:
        listed[conn.topic] += int(conn.msgcount)
    for topic, expected in sorted(listed.items()):
        if read[topic] != expected:
            report.issues.append(Issue(
                str(path), topic, None, 'count',
                f'the metadata lists {expected} messages but {read[topic]} were read '
                '(metadata.yaml edited, or written by another tool?)'))


def _check_alignment(path: Path, topics: dict[str, _Topic], report: IngestReport) -> set[int]:
    """Report gaps, missing steps and stamp mismatches; return the fully usable steps."""
    src = str(path)
    required = (TOPIC_STATE, TOPIC_STEP, TOPIC_CONTEXT_TRUTH)
    all_steps = set().union(*(topics[t].by_step for t in required))
    if not all_steps:
        return set()
    lo, hi = min(all_steps), max(all_steps)
    holes = sorted(set(range(lo, hi + 1)) - all_steps)
    for start, stop in _runs(holes):
        report.issues.append(Issue(src, TOPIC_STEP, start, 'gap',
                                   f'steps {start}..{stop} absent on every topic'))
    usable = set(all_steps)
    for topic in required:
        missing = sorted(all_steps - topics[topic].by_step.keys())
        usable -= set(missing)
        for start, stop in _runs(missing):
            report.issues.append(Issue(src, topic, start, 'gap',
                                       f'steps {start}..{stop} missing on this topic only'))
    ref = topics[TOPIC_STEP].by_step
    ref_steps, ref_stamps = list(ref), list(map(_STAMP, ref.values()))
    for topic in (TOPIC_STATE, TOPIC_CONTEXT_TRUTH, TOPIC_ACTION):
        by_step = topics[topic].by_step
        if list(by_step) == ref_steps and list(map(_STAMP, by_step.values())) == ref_stamps:
            continue  # the usual bag: the same steps with the same stamps
        for step, (stamp, _) in by_step.items():
            if step in ref and ref[step][0] != stamp:
                usable.discard(step)
                report.issues.append(Issue(
                    src, topic, step, 'stamp_mismatch',
                    f'stamp {stamp} ns != {TOPIC_STEP} stamp {ref[step][0]} ns'))
    return usable


def _runs(sorted_steps: list[int]) -> list[tuple[int, int]]:
    """Contiguous runs [(start, stop)] of a sorted list of ints."""
    runs: list[tuple[int, int]] = []
    for s in sorted_steps:
        if runs and runs[-1][1] == s - 1:
            runs[-1] = (runs[-1][0], s)
        else:
            runs.append((s, s))
    return runs


def _match_images(path: Path, steps: list[int], topics: dict[str, _Topic], store: FrameStore,
                  report: IngestReport) -> dict[int, Any]:
    """Give each step its frame by stamp (n-th image of a stamp -> n-th step of that stamp)."""
    fb = topics[TOPIC_STEP].by_step
    stamps = [fb[step][0] for step in steps]
    if len(set(stamps)) == len(stamps) and len(set(store.stamps)) == len(store.stamps):
        # the usual bag: one image per stamp, one step per stamp (refs are never None)
        found = list(map(dict(zip(store.stamps, store.refs, strict=True)).get, stamps))
        if None not in found:
            return dict(zip(steps, found, strict=True))
    images = store.by_stamp()
    by_stamp: dict[int, list[int]] = defaultdict(list)
    for step, stamp in zip(steps, stamps, strict=True):
        by_stamp[stamp].append(step)
    frames: dict[int, Any] = {}
    for stamp, stamp_steps in by_stamp.items():
        msgs = images.get(stamp, [])
        for i, step in enumerate(stamp_steps):
            if i < len(msgs):
                frames[step] = msgs[i]
            else:
                report.issues.append(Issue(str(path), TOPIC_IMAGE, step, 'gap',
                                           f'no image with stamp {stamp} ns'))
        if len(msgs) > len(stamp_steps):
            report.issues.append(Issue(str(path), TOPIC_IMAGE, stamp_steps[0], 'duplicate',
                                       f'{len(msgs)} images with stamp {stamp} ns'))
    return frames


def _bad_steps(steps: list[int], messages: list[Any], name: str, length: int | None,
               matrix: np.ndarray | None = None) -> dict[str, list[int]]:
    """Steps whose field `name` is of another length or not finite, by kind (vectorised).

    `matrix`: the field stacked (stack_field) when every message was decoded in one group.
    """
    bad: dict[str, list[int]] = {}
    if matrix is not None and matrix.shape[1] == length:  # one layout, all of that length
        rows = matrix.astype(np.float64)
    elif length is not None:
        values = [getattr(msg, name) for msg in messages]
        sized = np.fromiter((len(v) == length for v in values), bool, len(values))
        if not sized.all():
            bad['length'] = [steps[i] for i in np.flatnonzero(~sized)]
        rows = np.zeros((len(values), length))
        if sized.any():
            rows[sized] = np.stack([v for v, ok in zip(values, sized, strict=True) if ok])
    else:
        rows = np.asarray([getattr(msg, name) for msg in messages], np.float64).reshape(-1, 1)
    with np.errstate(invalid='ignore', over='ignore'):
        wrong = ~(np.isfinite(rows) & (np.abs(rows) <= MAX_ABS)).all(axis=1)
    if wrong.any():
        bad['nonfinite'] = [steps[i] for i in np.flatnonzero(wrong)]
    return bad


def _stacked(messages: list[Any], name: str) -> np.ndarray:
    """Field `name` of `messages` as one array, a row each (from the decoded group if it can)."""
    matrix = stack_field(messages, name)
    return np.stack([getattr(m, name) for m in messages]) if matrix is None else matrix


_FIELDS: tuple[tuple[str, str, bool, bool], ...] = (
    # topic, field, is a vector, bad data cuts before its step only (transition into it)
    (TOPIC_STATE, 'data', True, False),
    (TOPIC_CONTEXT_TRUTH, 'values', True, False),
    (TOPIC_STEP, 'reward', False, True),
    (TOPIC_STEP, 'applied_action', True, True),
    (TOPIC_ACTION, 'data', True, False),
)


def _check_values(path: Path, topics: dict[str, _Topic], report: IngestReport,
                  meta: dict[str, Any], namespace: str = '') -> tuple[set[int], set[int]]:
    """Find non-finite, huge and wrong-length fields; return (steps to drop, steps to cut before).

    The length most messages of a topic have sets its vector length (applied_action: among
    those that are not an episode start, which carries none). /zeus/action is the policy's
    request, not training data: a bad one is reported and read as absent. Lengths must also
    match earlier bags, else the bag is refused (IngestError): it was recorded on another task
    or robot.
    """
    drop: set[int] = set()
    cut: set[int] = set()
    lengths = meta.setdefault('lengths', {})
    in_order = {topic: _in_order(topics[topic].by_step, topic == TOPIC_STEP)
                for topic in _STEP_TOPICS}
    for topic, name, vector, cuts in _FIELDS:
        steps, messages = in_order[topic]
        if not steps:
            continue
        # One decoded group has one length: no need to count every message's (a view each).
        matrix = stack_field(messages, name) if vector else None
        length = (int(matrix.shape[1]) if matrix is not None
                  else _majority_length(messages, name)) if vector else None
        key = f'{topic} {name}'
        if length is not None and lengths.setdefault(key, length) != length:
            raise IngestError(f'{path}: {bag_topic(topic, namespace)} {name} has {length} '
                              f'values, earlier bags {lengths[key]}: recorded on another task '
                              'or robot; ingest them apart')
        bad = _bad_steps(steps, messages, name, length, matrix)
        for why, steps in bad.items():
            if topic == TOPIC_ACTION:
                effect = 'read as absent (the policy request is not trained on)'
            elif cuts:
                effect = 'the transition into each step is dropped'
                cut.update(steps)
            else:
                effect = "each step's transitions are dropped"
                drop.update(steps)
            detail = (f'{len(steps)} message(s) of another length than the {length} of most'
                      if why == 'length' else
                      f'{len(steps)} message(s) with NaN, Inf or |x| > {MAX_ABS:g}')
            first = ', '.join(map(str, steps[:_FIRST_STEPS]))
            more = ', ...' if len(steps) > _FIRST_STEPS else ''
            report.issues.append(Issue(str(path), bag_topic(topic, namespace), steps[0], why,
                                       f'{name}: {detail} at steps {first}{more}; {effect}'))
    return drop, cut


def _majority_length(messages: Sequence[Any], name: str) -> int:
    """The length most messages of a field have (ties: the earliest): the vector size.

    Not the first message's: one short first message would otherwise mark every good one.
    """
    lengths = Counter(len(getattr(m, name)) for m in messages)
    best = max(lengths.values())
    return next(n for n in (len(getattr(m, name)) for m in messages) if lengths[n] == best)


def _messages(by_step: dict[int, tuple[int, Any]], steps: Iterable[int]) -> Iterator[Any]:
    """The messages of `steps` (map chains: no Python frame per step)."""
    return map(_MESSAGE, map(by_step.__getitem__, steps))


def _in_order(by_step: dict[int, tuple[int, Any]], skip_first: bool = False
              ) -> tuple[list[int], list[Any]]:
    """Steps of a topic in order and their messages (StepFeedback: not an episode's first)."""
    steps = sorted(by_step)
    messages = list(_messages(by_step, steps))
    if skip_first:
        keep = [not m.first for m in messages]
        return list(compress(steps, keep)), list(compress(messages, keep))
    return steps, messages


def _pieces(path: Path, steps: list[int], fb: dict[int, tuple[int, Any]],
            report: IngestReport, cut: set[int] | None = None) -> list[list[int]]:
    """Split usable steps into contiguous runs of one episode each (and before `cut` steps)."""
    if not steps:
        return []
    msgs = list(_messages(fb, steps))
    count = len(steps)
    step = np.asarray(steps, np.int64)
    episode, episode_step = (np.fromiter(map(attrgetter(name), msgs), np.int64, count)
                             for name in ('episode', 'episode_step'))
    first, last = (np.fromiter(map(attrgetter(name), msgs), bool, count)
                   for name in ('first', 'last'))
    cont = np.zeros(count, bool)  # step i continues step i - 1's piece
    cont[1:] = ((step[1:] == step[:-1] + 1) & ~first[1:] & ~last[:-1]
                & (episode[1:] == episode[:-1]))
    if cut:
        cont &= ~np.isin(step, np.fromiter(cut, np.int64, len(cut)))
    skips = np.zeros(count, bool)
    skips[1:] = cont[1:] & (episode_step[1:] != episode_step[:-1] + 1)
    for i in np.flatnonzero(skips).tolist():
        report.issues.append(Issue(str(path), TOPIC_STEP, steps[i], 'episode',
                                   f'episode_step {episode_step[i]} does not follow '
                                   f'{episode_step[i - 1]}'))
    starts = np.flatnonzero(~(cont & ~skips)).tolist()
    return [steps[a:b] for a, b in zip(starts, [*starts[1:], count], strict=True) if b - a >= 2]


def _build_episode(path: Path, piece: list[int], topics: dict[str, _Topic],
                   frames: dict[int, Any] | None, store: FrameStore, action_dim: int
                   ) -> Episode:
    fb = list(_messages(topics[TOPIC_STEP].by_step, piece))
    truth = list(_messages(topics[TOPIC_CONTEXT_TRUTH].by_step, piece))
    acts = topics[TOPIC_ACTION].by_step
    policy = np.full((len(piece), action_dim), np.nan, np.float32)
    matrix = (stack_field(list(_messages(acts, piece)), 'data')
              if all(map(acts.__contains__, piece)) else None)
    if matrix is not None and matrix.shape[1] == action_dim:  # the usual bag: one at each step
        where, rows = np.arange(len(piece)), matrix.astype(np.float64)
    else:
        present = [(i, acts[s][1]) for i, s in enumerate(piece)
                   if s in acts and len(acts[s][1].data) == action_dim]
        where = np.asarray([i for i, _ in present], np.intp)
        rows = _stacked([msg for _, msg in present], 'data').astype(np.float64) \
            if present else None
    if rows is not None:  # a request of another length or with a bad value stays absent (NaN)
        with np.errstate(invalid='ignore'):
            usable = (np.isfinite(rows) & (np.abs(rows) <= MAX_ABS)).all(axis=1)
        policy[where[usable]] = rows[usable]
    pix = store.stack([frames[s] for s in piece]) if frames is not None else None
    return Episode(
        source=str(path),
        episode=int(fb[0].episode),
        steps=np.asarray(piece, np.int64),
        stamps_ns=np.fromiter(map(_STAMP, map(topics[TOPIC_STEP].by_step.__getitem__, piece)),
                              np.int64, len(piece)),
        obs=_stacked(list(_messages(topics[TOPIC_STATE].by_step, piece)), 'data'),
        frames=pix,
        action=_stacked(fb[1:], 'applied_action').astype(np.float32),
        action_status=np.asarray([m.action_status for m in fb[1:]], np.uint8),
        policy_action=policy,
        reward=np.asarray([m.reward for m in fb[1:]], np.float64),
        first=np.asarray([m.first for m in fb], bool),
        last=np.asarray([m.last for m in fb], bool),
        episode_step=np.asarray([m.episode_step for m in fb], np.int64),
        context=_stacked(truth, 'values').astype(np.float64),
        segment=np.asarray([m.segment for m in truth], np.int64),
    )


def _ingest_one(path: Path, report: IngestReport, meta: dict[str, Any],
                namespace: str = '') -> list[Episode]:
    # Every message read stays alive until the episodes are built, and none forms a cycle:
    # the cycle collector would only re-walk them, ever more often (half the time at 20k steps).
    collecting = gc.isenabled()
    gc.disable()
    try:
        return _ingest_read(path, report, meta, namespace)
    finally:
        if collecting:
            gc.enable()


def _ingest_read(path: Path, report: IngestReport, meta: dict[str, Any],
                 namespace: str = '') -> list[Episode]:
    read = _read_bag(path, report, namespace)
    topics: dict[str, _Topic] = read['topics']
    usable = _check_alignment(path, topics, report)
    fb = topics[TOPIC_STEP].by_step
    tasks = set(map(attrgetter('task'), _messages(fb, usable)))
    if len(tasks) > 1 or (tasks and meta.setdefault('task', next(iter(tasks))) not in tasks):
        for step in list(usable):  # name the first step of another task
            msg = fb[step][1]
            if msg.task != meta.setdefault('task', msg.task):
                raise IngestError(f'{path}: {TOPIC_STEP} step {step} is task {msg.task!r}, '
                                  f'earlier bags are {meta["task"]!r}; ingest one task at a time')
    truth = topics[TOPIC_CONTEXT_TRUTH].by_step
    names = set(map(tuple, map(attrgetter('names'), _messages(truth, truth))))
    for n in names:
        if n != meta.setdefault('names', n):
            raise IngestError(f'{path}: {TOPIC_CONTEXT_TRUTH} names {list(n)} differ from '
                              f'{list(meta["names"])} seen before')
    frames = None
    if read['frames'].read:
        frames = _match_images(path, sorted(usable), topics, read['frames'], report)
        usable &= frames.keys()
    drop, cut = _check_values(path, topics, report, meta, namespace)
    before = _pieces(path, sorted(usable), fb, IngestReport()) if drop or cut else []
    usable -= drop
    steps = sorted(usable)
    report.steps += len(steps)
    acting = [m for m in _messages(fb, usable - cut) if not m.first]
    matrix = stack_field(acting, 'applied_action')  # one group: one length
    action_dims = ({matrix.shape[1]} if matrix is not None
                   else {m.applied_action.shape[0] for m in acting})
    if len(action_dims) > 1:
        raise IngestError(f'{path}: {TOPIC_STEP} applied_action lengths differ: {action_dims}')
    action_dim = action_dims.pop() if action_dims else 0
    pieces = _pieces(path, steps, fb, report, cut)
    if drop or cut:
        report.dropped += (sum(len(p) - 1 for p in before)
                           - sum(len(p) - 1 for p in pieces))
    return [_build_episode(path, p, topics, frames, read['frames'], action_dim) for p in pieces]


def ingest_bags(
    paths: Path | str | Sequence[Path | str],
    *,
    skip_corrupt: bool = False,
    strict: bool = False,
    namespace: str = '',
) -> Dataset:
    """Read bags into a Dataset of step-aligned episodes.

    `paths`: bag directories, .mcap/.db3 files, or directories holding bags. A corrupt or
    truncated bag raises BagError naming it, or with `skip_corrupt` is skipped and listed in
    `report.skipped`. Gaps, duplicates, stamp mismatches and metadata counts that differ from
    what was read are listed in `report.issues` and warned about (IngestWarning); with `strict`
    they raise IngestError instead. `namespace`: the system's namespace when the bag holds
    /<namespace>/zeus/... topics (`ros2 bag record` of a namespaced system).
    """
    start = time.perf_counter()
    report = IngestReport()
    meta: dict[str, Any] = {}
    episodes: list[Episode] = []
    for bag in find_bags(paths):
        before = len(report.issues)
        try:
            eps = _ingest_one(bag, report, meta, namespace)
        except BagError as exc:
            if not skip_corrupt:
                raise
            report.skipped.append((str(bag), exc.reason))
            warnings.warn(f'skipping corrupt bag {exc}', IngestWarning, stacklevel=2)
            continue
        episodes.extend(eps)
        report.bags.append(str(bag))
        report.file_bytes += sum(f.stat().st_size for f in _bag_files(bag))
        new = report.issues[before:]
        if new:
            listed = '\n  '.join(map(str, new[:_MAX_LISTED]))
            more = f'\n  ... and {len(new) - _MAX_LISTED} more' if len(new) > _MAX_LISTED else ''
            if strict:
                raise IngestError(f'{bag}: {len(new)} issue(s) (--strict: the bag is refused):'
                                  f'\n  {listed}{more}')
            warnings.warn(f'{bag}: {len(new)} issue(s):\n  {listed}{more}', IngestWarning,
                          stacklevel=2)
    report.seconds = time.perf_counter() - start
    if not episodes:
        raise IngestError(f'no usable episode in {paths}: {report.summary()}')
    return Dataset(task=meta.get('task', ''), context_names=tuple(meta.get('names', ())),
                   episodes=episodes, report=report)


def _bag_files(bag: Path) -> list[Path]:
    return [bag] if bag.is_file() else [f for f in bag.iterdir() if f.is_file()]
