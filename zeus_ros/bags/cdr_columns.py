"""Decode many CDR messages of one zeus step type at once, column by column (for ingest).

Why: decoding message by message costs rosbags ~30 us each, most of ingest's time. The step
types (StateVector, StepFeedback, ContextTruth, Action) have a fixed byte layout once their
string and sequence lengths are known, so messages of equal size are stacked into one uint8
array and every field is read for all of them with one numpy view. A group's layout is taken
from its first message, every message of the group must carry the same length prefixes, and
the first message is checked against rosbags' own decoding: anything that does not fit (big
endian, another layout, a decoding disagreement) goes through `fallback` one by one, so the
result is always what rosbags would give.

Images (PAYLOAD_FIELDS) are decoded the same way, except that their pixel bytes are never
copied into the batch: only the bytes before them are, and each message's `data` is a numpy
view of its own raw bytes (a copy of every frame measured slower than rosbags itself).
"""

from __future__ import annotations

from collections import defaultdict, namedtuple
from collections.abc import Callable, Iterable, Sequence
from dataclasses import fields
from functools import cache
from itertools import repeat
from operator import attrgetter, is_
import struct
from types import SimpleNamespace
from typing import Any

import numpy as np

__all__ = ['FIELDS', 'PAYLOAD_FIELDS', 'decode_messages', 'payload_offset', 'stack_field']

FIELDS: dict[str, tuple[tuple[str, str], ...]] = {
    'zeus_msgs/msg/StateVector': (('step', 'u8'), ('data', 'f8[]')),
    'zeus_msgs/msg/StepFeedback': (
        ('step', 'u8'), ('episode', 'u4'), ('episode_step', 'u4'), ('first', 'b1'),
        ('last', 'b1'), ('reward', 'f8'), ('applied_action', 'f4[]'), ('action_status', 'u1'),
        ('task', 'str')),
    'zeus_msgs/msg/ContextTruth': (
        ('step', 'u8'), ('names', 'str[]'), ('values', 'f8[]'), ('segment', 'u4')),
    'zeus_msgs/msg/Action': (('step', 'u8'), ('data', 'f4[]')),
}
"""Fields after std_msgs/Header, in wire order (msg_defs/msg/*.msg)."""
PAYLOAD_FIELDS: dict[str, tuple[tuple[str, str], ...]] = {
    'sensor_msgs/msg/Image': (
        ('height', 'u4'), ('width', 'u4'), ('encoding', 'str'), ('is_bigendian', 'u1'),
        ('step', 'u4'), ('data', 'u1[]')),
}
"""Types whose last field is a byte payload, left in place (a view per message), as FIELDS."""
_SPECS = {**FIELDS, **PAYLOAD_FIELDS}
_DTYPES = {'u8': '<u8', 'u4': '<u4', 'u1': 'u1', 'b1': 'u1', 'f8': '<f8', 'f4': '<f4',
           'i4': '<i4'}
_U32 = struct.Struct('<I')
_CDR_LE = b'\x00\x01'

# One field of a layout: (name, kind, offset, count); for 'str' count is the byte length with
# its NUL, for 'str[]' offset/count are lists of each item's.
_Item = tuple[str, str, Any, Any]


def _align(pos: int, size: int) -> int:
    """CDR aligns to the field size, counted from the end of the 4-byte encapsulation header."""
    return pos + (-(pos - 4) % size)


def _layout(raw: bytes, spec: Sequence[tuple[str, str]]) -> tuple[list[_Item], list[int], int]:
    """Offsets of every field of one message, the positions of its length prefixes, its end."""
    items: list[_Item] = [('sec', 'i4', 4, 1), ('nanosec', 'u4', 8, 1)]
    prefixes = [12]
    length = _U32.unpack_from(raw, 12)[0]
    items.append(('frame_id', 'str', 16, length))
    pos = 16 + length
    for name, kind in spec:
        if kind == 'str':
            pos = _align(pos, 4)
            prefixes.append(pos)
            length = _U32.unpack_from(raw, pos)[0]
            items.append((name, kind, pos + 4, length))
            pos += 4 + length
        elif kind == 'str[]':
            pos = _align(pos, 4)
            prefixes.append(pos)
            count = _U32.unpack_from(raw, pos)[0]
            pos += 4
            offsets, lengths = [], []
            for _ in range(count):
                pos = _align(pos, 4)
                prefixes.append(pos)
                length = _U32.unpack_from(raw, pos)[0]
                offsets.append(pos + 4)
                lengths.append(length)
                pos += 4 + length
            items.append((name, kind, offsets, lengths))
        elif kind.endswith('[]'):
            size = np.dtype(_DTYPES[kind[:-2]]).itemsize
            pos = _align(pos, 4)
            prefixes.append(pos)
            count = _U32.unpack_from(raw, pos)[0]
            pos += 4
            if count:
                pos = _align(pos, size)
            items.append((name, kind, pos, count))
            pos += count * size
        else:
            size = np.dtype(_DTYPES[kind]).itemsize
            pos = _align(pos, size)
            items.append((name, kind, pos, 1))
            pos += size
    return items, prefixes, pos


def payload_offset(raw: bytes, msgtype: str) -> int | None:
    """Offset of the trailing byte payload of `raw` (a PAYLOAD_FIELDS type); None if unreadable."""
    try:
        items, _prefixes, _end = _layout(raw, PAYLOAD_FIELDS[msgtype])
    except struct.error:
        return None
    return int(items[-1][2])


def _strings(block: np.ndarray, offset: int, length: int) -> list[str]:
    """One string field of every row (decoded once per distinct value)."""
    if length <= 1:
        return [''] * block.shape[0]
    chars = block[:, offset:offset + length - 1]
    if (chars == chars[0]).all():  # the usual case: one task, one set of context names
        return [bytes(chars[0]).decode()] * block.shape[0]
    distinct, inverse = np.unique(chars, axis=0, return_inverse=True)
    texts = [bytes(row).decode() for row in distinct]
    return [texts[i] for i in inverse.ravel()]


def _columns(block: np.ndarray, items: list[_Item], matrices: dict[str, np.ndarray]
             ) -> dict[str, Iterable[Any]]:
    """Every field of every row of `block` (rows: messages of one layout).

    Each sequence of numbers is also put in `matrices` as one 2-D array (a row per message),
    which the per-message arrays are views of (stack_field).
    """
    rows = block.shape[0]
    columns: dict[str, Iterable[Any]] = {}
    for name, kind, offset, count in items:
        if kind == 'str':
            columns[name] = _strings(block, offset, count)
        elif kind == 'str[]':
            parts = [_strings(block, o, n) for o, n in zip(offset, count, strict=True)]
            columns[name] = [list(row) for row in zip(*parts, strict=True)] if parts \
                else [[] for _ in range(rows)]
        elif kind.endswith('[]'):
            dtype = np.dtype(_DTYPES[kind[:-2]])
            values = np.ascontiguousarray(block[:, offset:offset + count * dtype.itemsize])
            matrices[name] = values.view(dtype).reshape(rows, count)
            columns[name] = repeat(None, rows)  # the record reads its row (_record_type)
        else:
            dtype = np.dtype(_DTYPES[kind])
            values = np.ascontiguousarray(block[:, offset:offset + dtype.itemsize])
            column = values.view(dtype).ravel()
            columns[name] = (column.astype(bool) if kind == 'b1' else column).tolist()
    return columns


def _same(ours: Any, theirs: Any) -> bool:
    """One field as decoded here equals rosbags' decoding (arrays by value and dtype)."""
    if isinstance(theirs, np.ndarray):
        return isinstance(ours, np.ndarray) and ours.dtype == theirs.dtype and \
            np.array_equal(ours, theirs, equal_nan=True)
    if isinstance(theirs, list | tuple):
        return list(ours) == list(theirs)
    return type(ours) is type(theirs) and ours == theirs


def _agrees(message: SimpleNamespace, reference: Any, spec: Sequence[tuple[str, str]]
            ) -> bool:
    """The first message of a group decodes here exactly as `fallback` decodes it."""
    stamp = reference.header.stamp
    return (message.stamp_ns == stamp.sec * 1_000_000_000 + stamp.nanosec
            and all(_same(getattr(message, name), getattr(reference, name))
                    for name, _kind in spec))


def decode_messages(raws: Sequence[bytes], msgtype: str, fallback: Callable[[int], Any]
                    ) -> list[Any]:
    """Decode `raws` (CDR of `msgtype`) in order; `fallback(i)` decodes raws[i] alone.

    Returns one object per message with the type's fields as attributes (sequences of
    numbers as numpy arrays, as rosbags gives them) and `stamp_ns`, the header stamp in
    nanoseconds; read them by name, not by unpacking. Messages the fallback decodes are
    rosbags' own objects, with `stamp_ns` added. Errors come from `fallback` (a corrupt
    message).
    """
    spec = _SPECS[msgtype]
    out: list[Any] = [None] * len(raws)
    sizes = list(map(len, raws))
    by_size: dict[int, list[int]] = defaultdict(list)
    if sizes and min(sizes) == max(sizes):  # the usual topic: one size, one group
        by_size[sizes[0]] = list(range(len(raws)))
    else:
        for index, size in enumerate(sizes):
            by_size[size].append(index)
    slow: list[int] = []
    for size, indices in by_size.items():
        slow += _decode_group(raws, indices, size, spec, fallback, out)
    for index in slow:
        message = fallback(index)
        stamp = message.header.stamp
        out[index] = _with_stamp(message, stamp.sec * 1_000_000_000 + stamp.nanosec)
    return out


_GROUP, _ROW = attrgetter('group'), attrgetter('row')


@cache
def _record_type(names: tuple[str, ...], rows: frozenset[str] = frozenset()) -> Any:
    """A light read-only message: its fields, stamp_ns, and its group's matrices and row.

    Fields in `rows` (sequences of numbers) are read from the group's matrix when asked for:
    a view per message and field, made for all of them up front, cost more than the few reads.
    """
    record = namedtuple('CdrRecord', [*names, 'stamp_ns', 'group', 'row'])
    views = {name: property(lambda self, name=name: self.group[name][self.row])
             for name in rows}
    return type('CdrRecord', (record,), {'__slots__': (), **views}) if views else record


def stack_field(messages: Sequence[Any], name: str) -> np.ndarray | None:
    """`np.stack` of field `name` of `messages`, taken from their group's 2-D array at once.

    Why: stacking tens of thousands of row views one by one was a good part of ingest. Works
    when every message was decoded in one group (the usual bag: one layout per topic); else
    None, and the caller stacks as before. The result is a new array either way.
    """
    group = getattr(messages[0], 'group', None) if messages else None
    if group is None or name not in group:
        return None
    try:  # map(attrgetter): no Python frame per message
        if not all(map(is_, map(_GROUP, messages), repeat(group))):  # another group
            return None
    except AttributeError:  # a message decoded alone (the fallback) is among them
        return None
    return group[name][np.fromiter(map(_ROW, messages), np.intp, len(messages))]


def _with_stamp(message: Any, stamp_ns: int) -> Any:
    """The fallback's message as a namespace with the fast path's stamp_ns added."""
    return SimpleNamespace(**{f.name: getattr(message, f.name) for f in fields(message)},
                           stamp_ns=stamp_ns)


def _decode_group(raws: Sequence[bytes], indices: list[int], size: int,
                  spec: Sequence[tuple[str, str]], fallback: Callable[[int], Any],
                  out: list[Any]) -> list[int]:
    """Decode the messages of one size that share the first one's layout; return the rest."""
    first = raws[indices[0]]
    try:
        items, prefixes, end = _layout(first, spec)
    except struct.error:
        return indices
    if first[:2] != _CDR_LE or end > size or size - end > 7:  # only padding may follow
        return indices
    # A trailing byte payload (an image's pixels) stays where it is: only the bytes before it
    # are batched (its length prefix among them), and each message gets a view of its own.
    payload = items.pop() if items[-1][1] == 'u1[]' else None
    head = payload[2] if payload is not None else size
    group = raws if len(indices) == len(raws) else list(map(raws.__getitem__, indices))
    parts = (raw[:head] for raw in group) if payload is not None else group
    block = np.frombuffer(b''.join(parts), np.uint8).reshape(-1, head)
    fits = (block[:, 0] == 0) & (block[:, 1] == 1)
    for pos in prefixes:
        fits &= (block[:, pos:pos + 4] == block[0, pos:pos + 4]).all(axis=1)
    every = bool(fits.all())
    block = block if every else block[fits]
    matrices: dict[str, np.ndarray] = {}
    columns = _columns(block, items[3:], matrices)  # after the header's sec, nanosec, frame_id
    record = _record_type(tuple(name for name, _kind in spec), frozenset(matrices))
    members = indices if every else [i for i, ok in zip(indices, fits.tolist(), strict=True)
                                     if ok]
    if payload is not None:
        columns[payload[0]] = [np.frombuffer(raws[i], np.uint8, payload[3], head)
                               for i in members]
    stamp = np.ascontiguousarray(block[:, 4:12])  # header.stamp: sec int32, nanosec uint32
    stamps = (stamp[:, :4].copy().view('<i4').astype(np.int64) * 1_000_000_000
              + stamp[:, 4:].copy().view('<u4')).ravel().tolist()
    rows = zip(*(columns[name] for name in record._fields[:-3]), stamps,
               repeat(matrices, len(members)), range(len(members)), strict=True)
    records = map(tuple.__new__, repeat(record), rows)  # record._make without its frame
    if every and len(members) == len(out):
        out[:] = records
    else:
        for index, message in zip(members, records, strict=True):
            out[index] = message
    if not _agrees(out[members[0]], fallback(members[0]), spec):
        for index in members:
            out[index] = None
        return indices
    return [] if every else [i for i, ok in zip(indices, fits.tolist(), strict=True) if not ok]
