"""Recovery: turn what a killed recorder left on disk back into a bag every reader opens.

`zeus recover` (zeus_ros/cli/recover.py) runs it on folders of bags. The writer side of crash
durability (periodic flush, provisional metadata.yaml) is
`zeus_ros.bags.durable.DurableBagWriter`; this module reads what it leaves behind.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from pathlib import Path
import shutil
import sqlite3
import struct
from typing import TYPE_CHECKING

from rosbags.rosbag2 import Reader, StoragePlugin
from rosbags.rosbag2.storage_mcap import decompress, get_qos
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from ruamel.yaml import YAML

from zeus_ros.atomic_file import replace_text
from zeus_ros.bags.durable import STATE_KEY, bag_metadata
from zeus_ros.bags.errors import BagError
from zeus_ros.bags.mcap_file import closed_by_writer
from zeus_ros.bags.schema import MSGTYPES, typestore
from zeus_ros.bags.writer import BAG_VERSION, JazzyWriter

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ['STEP_TOPICS', 'RecoveryReport', 'bag_state', 'needs_recovery', 'recover_bag',
           'stamp_from_cdr', 'step_from_cdr']

STEP_TOPICS = frozenset(t for t, typ in MSGTYPES.items() if typ.startswith('zeus_msgs/'))
"""Topics whose messages start with `std_msgs/Header header` then `uint64 step`."""
_MAGIC = b'\x89MCAP0\r\n'


def step_from_cdr(data: bytes | memoryview) -> int | None:
    """The `step` of a zeus message straight from its CDR bytes (no full deserialization)."""
    raw = memoryview(data)
    if len(raw) < 16:
        return None
    order = '<' if raw[1] & 1 else '>'
    (strlen,) = struct.unpack_from(f'{order}I', raw, 4 + 8)
    pos = 4 + ((12 + strlen + 7) & ~7)  # CDR aligns relative to the end of the 4-byte prefix
    if pos + 8 > len(raw):
        return None
    return int(struct.unpack_from(f'{order}Q', raw, pos)[0])


def stamp_from_cdr(data: bytes | memoryview) -> int | None:
    """Nanoseconds of the leading Time (header.stamp, or Clock.clock) of a message's CDR bytes."""
    raw = memoryview(data)
    if len(raw) < 12:
        return None
    sec, nanosec = struct.unpack_from('<iI' if raw[1] & 1 else '>iI', raw, 4)
    return sec * 1_000_000_000 + nanosec


@dataclass
class RecoveryReport:
    """What `recover_bag` found: messages kept per topic, the last step, what was lost."""

    path: Path
    storage: str
    status: str
    """intact | recovered | would-recover (dry run)."""
    counts: dict[str, int] = field(default_factory=dict)
    last_step: dict[str, int] = field(default_factory=dict)
    dropped_bytes: int = 0
    notes: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """Human-readable lines for the terminal."""
        if self.status == 'intact':
            return f'{self.path} [{self.storage}]: closed properly, nothing to recover'
        lines = [f'{self.path} [{self.storage}]: {self.status}, '
                 f'{sum(self.counts.values())} messages kept']
        for topic in sorted(self.counts):
            last = self.last_step.get(topic)
            lines.append(f'  {topic}: {self.counts[topic]} messages'
                         + (f', last step {last}' if last is not None else ''))
        if self.dropped_bytes:
            lines.append(f'  dropped: an incomplete tail of {self.dropped_bytes} bytes after the '
                         'last complete record (written after the last flush)')
        lines += [f'  note: {n}' for n in self.notes]
        return '\n'.join(lines)


@dataclass
class _Mcap:
    """Records salvaged from a (possibly truncated) mcap file."""

    schemas: dict[int, tuple[str, str, str]] = field(default_factory=dict)
    channels: dict[int, tuple[int, str, str, bytes]] = field(default_factory=dict)
    messages: list[tuple[int, int, bytes]] = field(default_factory=list)
    good_end: int = 0
    size: int = 0
    partial: int = 0
    """Messages taken from a chunk whose write was cut off."""


def _string(buf: memoryview, pos: int) -> tuple[str, int]:
    (n,) = struct.unpack_from('<I', buf, pos)
    return bytes(buf[pos + 4:pos + 4 + n]).decode(), pos + 4 + n


def _records(buf: memoryview, scan: _Mcap, top: bool) -> int:
    """Parse records from `buf` into `scan`; return where the last complete record ended."""
    pos = 0
    while pos + 9 <= len(buf):
        op, length = buf[pos], struct.unpack_from('<Q', buf, pos + 1)[0]
        body = buf[pos + 9:pos + 9 + length]
        if len(body) < length:
            if top and op == 0x06:  # a chunk cut mid-write: keep its complete messages
                _chunk(body, scan, partial=True)
            break
        if op == 0x03:
            (sid,) = struct.unpack_from('<H', body, 0)
            name, p = _string(body, 2)
            enc, p = _string(body, p)
            (n,) = struct.unpack_from('<I', body, p)
            scan.schemas[sid] = (name, enc, bytes(body[p + 4:p + 4 + n]).decode())
        elif op == 0x04:
            cid, sid = struct.unpack_from('<HH', body, 0)
            topic, p = _string(body, 4)
            enc, p = _string(body, p)
            (n,) = struct.unpack_from('<I', body, p)
            scan.channels[cid] = (sid, topic, enc, bytes(body[p:p + 4 + n]))
        elif op == 0x05:
            (cid,) = struct.unpack_from('<H', body, 0)
            (log_time,) = struct.unpack_from('<Q', body, 6)
            scan.messages.append((cid, log_time, bytes(body[22:])))
        elif op == 0x06 and top:
            _chunk(body, scan, partial=False)
        elif op == 0x0F and top:  # DataEnd: the summary section follows
            return pos + 9 + length
        pos += 9 + length
    return pos


def _chunk(body: memoryview, scan: _Mcap, *, partial: bool) -> None:
    try:
        size, crc = struct.unpack_from('<QI', body, 16)
        compression, p = _string(body, 28)
        (n,) = struct.unpack_from('<Q', body, p)
    except (struct.error, UnicodeDecodeError):  # a chunk cut inside its own header
        return
    data = body[p + 8:p + 8 + n]
    if partial:
        if not compression:  # uncompressed: the complete records of the prefix are usable
            before = len(scan.messages)
            with contextlib.suppress(struct.error, UnicodeDecodeError):
                _records(data, scan, top=False)
            scan.partial += len(scan.messages) - before
        return
    _records(memoryview(decompress(bytes(data), compression, size, crc)), scan, top=False)


def _scan_mcap(path: Path) -> _Mcap:
    buf = memoryview(path.read_bytes())
    scan = _Mcap(size=len(buf))
    if bytes(buf[:8]) != _MAGIC:
        raise BagError(path, 'not an mcap file (bad magic)')
    header_len = struct.unpack_from('<Q', buf, 9)[0]
    start = 8 + 9 + header_len
    scan.good_end = start + _records(buf[start:], scan, top=True)
    return scan


def _rihs01(msgtype: str, msgdef: str) -> str:
    store = typestore()
    if msgtype not in store.types:
        store = get_typestore(Stores.ROS2_JAZZY)
        store.register(get_types_from_msg(msgdef, msgtype))
    return store.hash_rihs01(msgtype)


def _rebuild_mcap(bag: Path, mcap: Path, scan: _Mcap, report: RecoveryReport,
                  keep_original: bool) -> None:
    """Write the salvaged records to a fresh, finalized bag and swap it in."""
    tmp_root = bag.parent / f'.recover-{bag.name}'
    shutil.rmtree(tmp_root, ignore_errors=True)
    tmp_root.mkdir()
    tmp_bag = tmp_root / mcap.stem
    try:
        writer = JazzyWriter(tmp_bag, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        writer.set_custom_data(STATE_KEY, 'recovered')
        writer.open()
        conns = {}
        for cid, (sid, topic, _enc, meta) in sorted(scan.channels.items()):
            msgtype, _fmt, msgdef = scan.schemas[sid]
            conns[cid] = writer.add_connection(
                topic, msgtype, msgdef=msgdef, rihs01=_rihs01(msgtype, msgdef),
                offered_qos_profiles=get_qos(meta[4:]))
        for cid, log_time, data in scan.messages:
            writer.write(conns[cid], log_time, data)
        writer.close()
        if keep_original:
            mcap.replace(mcap.with_name(mcap.name + '.orig'))
        (tmp_bag / f'{mcap.stem}.mcap').replace(mcap)
        (tmp_bag / 'metadata.yaml').replace(bag / 'metadata.yaml')
    finally:
        shutil.rmtree(tmp_root, ignore_errors=True)
    report.status = 'recovered'


def _recover_mcap(bag: Path, mcap: Path, report: RecoveryReport, *, dry_run: bool,
                  keep_original: bool) -> None:
    scan = _scan_mcap(mcap)
    known = {cid for cid, ch in scan.channels.items() if ch[0] in scan.schemas}
    lost = [m for m in scan.messages if m[0] not in known]
    if lost:
        report.notes.append(f'{len(lost)} messages on channels without a schema were dropped')
        scan.messages = [m for m in scan.messages if m[0] in known]
    topic_of = {cid: ch[1] for cid, ch in scan.channels.items()}
    _tally(report, ((topic_of[c], d) for c, _t, d in scan.messages),
           [topic_of[c] for c in sorted(known)])
    report.dropped_bytes = scan.size - scan.good_end
    if scan.partial:
        report.notes.append(f'{scan.partial} messages kept from a chunk cut off mid-write')
    if not dry_run:
        _rebuild_mcap(bag, mcap, scan, report, keep_original)


def _recover_sqlite(bag: Path, db3: Path, report: RecoveryReport, *, dry_run: bool) -> None:
    """Committed rows survive a kill (the journal rolls back the rest): recount, rewrite yaml."""
    conn = sqlite3.connect(f'file:{db3}', uri=True)
    try:
        rows = conn.execute('SELECT id, name, type, serialization_format, offered_qos_profiles,'
                            ' type_description_hash FROM topics ORDER BY id').fetchall()
        span = conn.execute('SELECT MIN(timestamp), MAX(timestamp) FROM messages').fetchone()
        names = {r[0]: r[1] for r in rows}
        data = conn.execute('SELECT topic_id, data FROM messages ORDER BY id')
        _tally(report, ((names[tid], raw) for tid, raw in data), list(names.values()))
    finally:
        conn.close()
    yaml = YAML(typ='safe')
    topics = [{'name': r[1], 'type': r[2], 'serialization_format': r[3],
               'offered_qos_profiles': yaml.load(r[4] or '[]') or [],
               'type_description_hash': r[5],
               'message_count': report.counts[r[1]]} for r in rows]
    report.notes.append('inserts after the last commit (the last flush) are not in the file')
    if not dry_run:
        replace_text(bag / 'metadata.yaml', bag_metadata(
            'sqlite3', db3.name, topics, span[0] or 0, span[1] or 0, 'recovered'))
        report.status = 'recovered'


def _tally(report: RecoveryReport, messages: Iterable[tuple[str, bytes]],
           topics: list[str]) -> None:
    report.counts = dict.fromkeys(topics, 0)
    for topic, data in messages:
        report.counts[topic] += 1
        if topic in STEP_TOPICS:
            step = step_from_cdr(data)
            if step is not None and step >= report.last_step.get(topic, -1):
                report.last_step[topic] = step


def bag_state(bag: Path) -> str | None:
    """How a bag was left, from its metadata.yaml: 'closed', 'recovered', 'provisional'.

    'recovered': cut by a crash and rebuilt by `zeus recover`; 'unfinished': no metadata and
    no complete file (not closed); None when the metadata says nothing (not written by zeus) or
    a complete mcap has none (closed by another writer).
    """
    bag = bag.parent if bag.is_file() else bag
    meta = bag / 'metadata.yaml'
    if not meta.exists():
        mcaps = sorted(bag.glob('*.mcap'))
        # A complete mcap another writer closed without a metadata.yaml is not cut short.
        return None if len(mcaps) == 1 and closed_by_writer(mcaps[0]) else 'unfinished'
    try:
        info = YAML(typ='safe').load(meta.read_text('utf8'))['rosbag2_bagfile_information']
    except Exception:  # an unreadable metadata.yaml: ingest names what is wrong with it
        return None
    return (info.get('custom_data') or {}).get(STATE_KEY)


def needs_recovery(bag: Path) -> bool:
    """True when a bag directory was not closed (no or provisional metadata, unreadable)."""
    meta = bag / 'metadata.yaml'
    if not meta.exists():
        return True
    try:
        info = YAML(typ='safe').load(meta.read_text('utf8'))['rosbag2_bagfile_information']
        if (info.get('custom_data') or {}).get(STATE_KEY) == 'provisional':
            return True
        reader = Reader(bag)
        reader.open()
        reader.close()
    except Exception:  # rosbags raises ReaderError and storage-specific errors
        return True
    return False


def recover_bag(path: Path | str, *, dry_run: bool = False,
                keep_original: bool = False) -> RecoveryReport:
    """Restore one bag directory cut off by a crash (no-op on a bag that was closed properly)."""
    bag = Path(path)
    bag = bag.parent if bag.is_file() else bag
    files = sorted(bag.glob('*.mcap')) + sorted(bag.glob('*.db3'))
    if len(files) != 1:
        raise BagError(bag, f'expected one .mcap or .db3 file in the bag, found {len(files)}')
    storage = 'mcap' if files[0].suffix == '.mcap' else 'sqlite3'
    report = RecoveryReport(bag, storage, 'would-recover' if dry_run else 'intact')
    if not needs_recovery(bag):
        report.status = 'intact'
        return report
    if storage == 'mcap':
        _recover_mcap(bag, files[0], report, dry_run=dry_run, keep_original=keep_original)
    else:
        _recover_sqlite(bag, files[0], report, dry_run=dry_run)
    return report
