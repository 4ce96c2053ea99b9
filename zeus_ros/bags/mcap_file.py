"""What an .mcap file says apart from metadata.yaml: closed by its writer or not, channel QoS.

Why: a file another writer closed (no summary, no metadata.yaml beside it) is complete and must
not be called cut short by a crash; only a file without its footer is torn. And rosbags pairs
metadata.yaml's topics with the file's channels by their QoS too: where they differ, the
channel's messages are silently left unread, so the difference has to be found and named.
"""

from __future__ import annotations

from io import BytesIO
from pathlib import Path
import struct
from typing import TYPE_CHECKING, BinaryIO

from rosbags.rosbag2.storage_mcap import get_qos

if TYPE_CHECKING:
    from collections.abc import Iterator

    from rosbags.interfaces import Qos

__all__ = ['channel_qos', 'closed_by_writer', 'qos_text']

MAGIC = b'\x89MCAP0\r\n'
_FOOTER, _CHANNEL, _CHUNK, _DATA_END = 0x02, 0x04, 0x06, 0x0F
_FOOTER_LEN = 1 + 8 + 20  # opcode, length, summary_start, summary_offset_start, summary_crc


def closed_by_writer(path: Path) -> bool:
    """True when the file ends with a footer and the closing magic: its writer finished it.

    A crash or a full disk leaves no footer (`zeus recover` rebuilds such a file); any writer
    that closes a file writes one, with or without a summary section.
    """
    try:
        with path.open('rb') as handle:
            if handle.read(len(MAGIC)) != MAGIC:
                return False
            handle.seek(0, 2)
            size = handle.tell()
            if size < 2 * len(MAGIC) + _FOOTER_LEN:
                return False
            handle.seek(size - len(MAGIC) - _FOOTER_LEN)
            tail = handle.read()
    except OSError:
        return False
    return tail[0] == _FOOTER and struct.unpack_from('<Q', tail, 1)[0] == 20 \
        and tail.endswith(MAGIC)


def _records(handle: BinaryIO, start: int, end: int) -> Iterator[tuple[int, bytes | None]]:
    """(opcode, content) of the records in [start, end).

    Records other than chunks and channels are skipped unread (content None).
    """
    pos = start
    while pos + 9 <= end:
        handle.seek(pos)
        head = handle.read(9)
        if len(head) < 9:
            return
        opcode, length = head[0], struct.unpack_from('<Q', head, 1)[0]
        body = handle.read(length) if opcode in (_CHANNEL, _CHUNK) else None
        yield opcode, body
        if opcode in (_FOOTER, _DATA_END):
            return
        pos += 9 + length


def _string(buf: BytesIO) -> str:
    (size,) = struct.unpack('<I', buf.read(4))
    return buf.read(size).decode()


def _channel(body: bytes) -> tuple[str, list[Qos]]:
    buf = BytesIO(body)
    buf.read(4)  # channel id, schema id
    topic = _string(buf)
    _string(buf)  # message encoding
    (size,) = struct.unpack('<I', buf.read(4))
    return topic, get_qos(buf.read(size))


def _chunk_records(body: bytes) -> Iterator[tuple[int, bytes | None]]:
    """The records of an uncompressed chunk.

    A compressed one is skipped: the channels of such files are in their summary section.
    """
    buf = BytesIO(body)
    buf.read(8 + 8 + 8 + 4)  # start/end time, uncompressed size and crc
    if _string(buf):
        return
    (size,) = struct.unpack('<Q', buf.read(8))
    inner = BytesIO(buf.read(size))
    yield from _records(inner, 0, size)


def channel_qos(path: Path) -> dict[str, list[Qos]]:
    """Topic -> the offered QoS profiles its channel in the file holds (first channel wins).

    Read from the summary section when there is one, else from the data section (a file
    without a summary, or torn).
    """
    found: dict[str, list[Qos]] = {}
    with path.open('rb') as handle:
        handle.seek(0, 2)
        size = handle.tell()
        start, end = len(MAGIC), size
        if closed_by_writer(path):
            handle.seek(size - len(MAGIC) - 20)
            summary = struct.unpack('<Q', handle.read(8))[0]
            start, end = (summary, size - len(MAGIC) - _FOOTER_LEN) if summary else (start, end)
        for opcode, body in _records(handle, start, end):
            inner = _chunk_records(body) if opcode == _CHUNK and body else [(opcode, body)]
            for op, content in inner:
                if op == _CHANNEL and content is not None:
                    topic, qos = _channel(content)
                    found.setdefault(topic, qos)
    return found


def qos_text(profiles: list[Qos]) -> str:
    """'reliable volatile keep_last 1000' per profile: what an operator compares."""
    def one(qos: Qos) -> str:
        return (f'{qos.reliability.name.lower()} {qos.durability.name.lower()} '
                f'{qos.history.name.lower()} {qos.depth}')

    return ' | '.join(map(one, profiles)) or 'none'
