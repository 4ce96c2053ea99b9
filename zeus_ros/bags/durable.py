"""Crash durability of zeus bags, writer side: periodic flush and a provisional metadata.yaml.

rosbags' writers are only safe when closed: the sqlite3 writer commits at `close()`, the mcap
writer emits a chunk per ~1 MiB and the footer at `close()`, and the Reader refuses a bag with no
metadata.yaml. `DurableBagWriter` flushes a chunk / commits every `flush()` and keeps a
provisional metadata.yaml, so a killed recorder loses at most the data since its last flush;
`zeus recover` (recover.py) restores the rest.
"""

from __future__ import annotations

import contextlib
from io import StringIO
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer
from ruamel.yaml import YAML

from zeus_ros.atomic_file import injected_write_fault, replace_text
from zeus_ros.bags.kinds import BagLabel
from zeus_ros.bags.writer import (
    BAG_VERSION,
    ROS_DISTRO,
    QosSource,
    StepBagWriter,
    Storage,
)

if TYPE_CHECKING:
    from collections.abc import Sequence

__all__ = ['STATE_KEY', 'DurableBagWriter', 'bag_metadata']

STATE_KEY = 'zeus_bag_state'
"""custom_data key in metadata.yaml: 'provisional' while recording, then 'closed' / 'recovered'."""


def bag_metadata(storage: str, file_name: str, topics: Sequence[dict[str, Any]],
                 start_ns: int, end_ns: int, state: str) -> str:
    """metadata.yaml text (rosbag2 version 9), as JazzyWriter.close() writes it.

    Each topic's `offered_qos_profiles` is the version 9 list (rosbags' dump_qos_v9).
    """
    count = sum(int(t['message_count']) for t in topics)
    start = start_ns if count else 0
    duration = max(0, end_ns - start_ns) if count else 0
    info = {
        'version': BAG_VERSION,
        'storage_identifier': storage,
        'relative_file_paths': [file_name],
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': count,
        'topics_with_message_count': [
            {'topic_metadata': {k: t[k] for k in ('name', 'type', 'serialization_format',
                                                  'offered_qos_profiles',
                                                  'type_description_hash')},
             'message_count': int(t['message_count'])}
            for t in topics
        ],
        'compression_format': '',
        'compression_mode': '',
        'files': [{'path': file_name, 'starting_time': {'nanoseconds_since_epoch': start},
                   'duration': {'nanoseconds': duration}, 'message_count': count}],
        'custom_data': {STATE_KEY: state},
        'ros_distro': ROS_DISTRO,
    }
    yaml = YAML(typ='safe')
    yaml.default_flow_style = False
    text = StringIO()
    yaml.dump({'rosbag2_bagfile_information': info}, text)
    return text.getvalue()


class DurableBagWriter(StepBagWriter):
    """StepBagWriter whose `flush()` puts everything written so far on disk, readable after a kill.

    mcap: the pending chunk is closed and the file buffer flushed; sqlite3: the transaction is
    committed. Each flush also refreshes a provisional metadata.yaml (custom_data
    zeus_bag_state=provisional), which `close()` replaces with the final one.
    """

    def __init__(self, path: Path | str, *, storage: Storage = 'mcap', pixels: bool,
                 offered_qos: QosSource | None = None, label: BagLabel | None = None) -> None:
        super().__init__(path, storage=storage, pixels=pixels, offered_qos=offered_qos,
                         label=label)
        assert self._writer is not None
        self._writer.set_custom_data(STATE_KEY, 'closed')
        self.flushes = 0
        self.flush()

    @property
    def file_path(self) -> Path:
        """The .mcap / .db3 file inside the bag directory."""
        suffix = '.mcap' if self.storage == 'mcap' else '.db3'
        return self.path / f'{self.path.name}{suffix}'

    def flush(self) -> None:
        """Make every message written so far survive a SIGKILL; refresh the provisional yaml."""
        writer = self._writer
        if writer is None:
            return
        injected_write_fault(self.file_path)
        storage = writer.storage
        if isinstance(storage, McapWriter):
            if storage.chunk.msgs:  # a chunk holding only schemas waits for its first message
                storage.close_chunk()
            storage.bio.flush()
        elif isinstance(storage, Sqlite3Writer):
            storage.conn.commit()
        topics = [
            {'name': c.topic, 'type': c.msgtype, 'serialization_format': 'cdr',
             'offered_qos_profiles': dump_qos_v9(list(getattr(c.ext, 'offered_qos_profiles',
                                                               []))),
             'type_description_hash': c.digest,
             'message_count': writer.counts[c.id]}
            for c in writer.connections
        ]
        replace_text(writer.metapath, bag_metadata(
            self.storage, self.file_path.name, topics, writer.min_timestamp,
            writer.max_timestamp, 'provisional'))
        self.flushes += 1

    def abandon(self) -> None:
        """Let go of a bag that cannot be written (disk full, permission), writing nothing more.

        Its files stay as a crash leaves them: what was flushed and the provisional
        metadata.yaml, which `zeus recover` closes. A close would write the footer and the
        final metadata.yaml onto the failing disk, and could leave that metadata.yaml empty.
        """
        writer, self._writer = self._writer, None
        if writer is None:
            return
        storage = writer.storage
        handle = getattr(storage, 'bio', None)
        with contextlib.suppress(Exception):
            if handle is not None:  # the raw file: closing the buffer would write once more
                getattr(handle, 'raw', handle).close()
            elif isinstance(storage, Sqlite3Writer):
                storage.conn.close()  # the open transaction is rolled back
