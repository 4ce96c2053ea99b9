"""A bag's image pixels, channel-first, one row per image, copied in as the bag is read (ingest).

Why: holding every raw image until the episodes are built, then copying each frame out, cost
more than the read itself; copying each frame once, while its bytes are still in cache, and
handing episodes views of consecutive rows does not. An image whose height, width or data
length differ from the first image's is kept as its message instead, and an episode holding
one is built frame by frame with its first frame's shape.

Most batches skip decoding altogether (`add_raw`): once one image has been decoded (and checked
against rosbags, cdr_columns), an image whose CDR bytes before its pixels equal that one's in
all but the stamp decodes to the same fields, so only its stamp is read and its pixels copied.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np

from zeus_ros.bags.cdr_columns import payload_offset

__all__ = ['FrameStore']

_STAMP = slice(4, 12)
"""Bytes of header.stamp (sec int32, nanosec uint32) after the CDR encapsulation header."""


class FrameStore:
    """Rows of pixels and, per image read (in read order), its stamp and where it is."""

    def __init__(self, listed: int, bag_bytes: int, msgtype: str = 'sensor_msgs/msg/Image'
                 ) -> None:
        self._listed = listed
        """Images the bag's metadata lists (the store's first size, if the file can hold them)."""
        self._bag_bytes = bag_bytes
        self._msgtype = msgtype
        self.rows: np.ndarray | None = None
        self.count = 0
        """Rows filled."""
        self.stamps: list[int] = []
        """Header stamp (ns) of every image added, stored or not."""
        self.refs: list[Any] = []
        """Each image's row in `rows`, or its message if not of the first's shape."""
        self._head: np.ndarray | None = None
        """CDR bytes before the pixels of a stored image decoded by `add` (add_raw's model)."""
        self._size = 0

    @property
    def read(self) -> int:
        """Images added, stored or not."""
        return len(self.refs)

    def _room(self, count: int) -> np.ndarray:
        """`rows`, grown (doubled) until `count` more fit: a bag may hold more than listed."""
        assert self.rows is not None
        while self.count + count > len(self.rows):
            self.rows = np.concatenate([self.rows, np.empty_like(self.rows)])
        return self.rows

    def add(self, messages: list[Any], raws: list[bytes] | None = None) -> list[Any]:
        """Store decoded images (with stamp_ns); learn add_raw's model from `raws` if given."""
        refs: list[Any] = []
        for msg in messages:
            height, width, data = int(msg.height), int(msg.width), msg.data
            if self.rows is None:  # an uncompressed bag holds at most bag_bytes // frame bytes
                size = min(self._listed, self._bag_bytes // max(3 * height * width, 1))
                self.rows = np.empty((max(size, 1), 3, height, width), np.uint8)
            if self.rows.shape[2:] != (height, width) or data.size != 3 * height * width:
                refs.append(msg)
                continue
            self._room(1)[self.count] = data.reshape(height, width, 3).transpose(2, 0, 1)
            refs.append(self.count)
            self.count += 1
        self.stamps += [msg.stamp_ns for msg in messages]
        self.refs += refs
        if raws is not None and self._head is None:
            self._learn(messages, raws, refs)
        return refs

    def _learn(self, messages: list[Any], raws: list[bytes], refs: list[Any]) -> None:
        """Keep the bytes before the pixels of the first stored image decoded in a batch."""
        for msg, raw, ref in zip(messages, raws, refs, strict=True):
            if type(ref) is int and hasattr(msg, 'row'):  # batch-decoded (cdr_columns), stored
                offset = payload_offset(raw, self._msgtype)
                if offset is not None and offset + msg.data.size <= len(raw):
                    self._head = np.frombuffer(raw, np.uint8, offset)
                    self._size = len(raw)
                return

    def add_raw(self, raws: list[bytes]) -> bool:
        """Store images from their CDR bytes alone if all equal the model but in stamp and pixels.

        Else store nothing and return False: the caller decodes them and calls `add`.
        """
        head = self._head
        if head is None or not raws or set(map(len, raws)) != {self._size}:
            return False
        offset = head.size
        block = np.frombuffer(b''.join([raw[:offset] for raw in raws]), np.uint8)
        block = block.reshape(len(raws), offset)
        if not ((block[:, :_STAMP.start] == head[:_STAMP.start]).all()
                and (block[:, _STAMP.stop:] == head[_STAMP.stop:]).all()):
            return False
        stamp = np.ascontiguousarray(block[:, _STAMP])
        sec, nanosec = stamp[:, :4].copy().view('<i4'), stamp[:, 4:].copy().view('<u4')
        self.stamps += (sec.astype(np.int64) * 1_000_000_000 + nanosec).ravel().tolist()
        rows = self._room(len(raws))
        _, height, width = rows.shape[1:]
        pixels = rows.transpose(0, 2, 3, 1)  # (N, H, W, 3) view: each copy lands channel-first
        size, start = 3 * height * width, self.count
        for index, raw in enumerate(raws, start):
            pixels[index] = np.frombuffer(raw, np.uint8, size, offset).reshape(height, width, 3)
        self.count += len(raws)
        self.refs += range(start, self.count)
        return True

    def by_stamp(self) -> dict[int, list[Any]]:
        """Refs of the images read, by stamp, in read order."""
        images: dict[int, list[Any]] = defaultdict(list)
        for stamp, ref in zip(self.stamps, self.refs, strict=True):
            images[stamp].append(ref)
        return images

    def stack(self, refs: list[Any]) -> np.ndarray:
        """(len(refs), 3, H, W) frames of `refs` (rows or messages, from add)."""
        rows, start = self.rows, refs[0]
        if type(start) is int and refs == list(range(start, start + len(refs))):
            return rows[start:start + len(refs)]  # the usual case: no copy (a message != int)
        if rows is not None and all(type(r) is int for r in refs):
            return rows[refs]
        datas = [r.data if type(r) is not int else rows[r].transpose(1, 2, 0).reshape(-1)
                 for r in refs]
        first = refs[0]
        height, width = (rows.shape[2:] if type(first) is int
                         else (int(first.height), int(first.width)))
        pix = np.empty((len(refs), 3, height, width), np.uint8)
        for i, data in enumerate(datas):
            pix[i] = data.reshape(height, width, 3).transpose(2, 0, 1)
        return pix
