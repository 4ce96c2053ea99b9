"""A bag whose disk fails mid-recording (the recorder's path): dropped as a crash leaves it.

In-process, both storages: flushes succeed, then $ZEUS_WRITE_FAULT fails the next one, the
writer lets go of the bag (DurableBagWriter.abandon) and `zeus recover` closes what it flushed.
The recorder node doing this under `zeus launch` is test/faults/test_fault_logging.py.
"""

from __future__ import annotations

import errno
from pathlib import Path

import pytest
from test_bags import _write_synthetic

from zeus_ros.atomic_file import WRITE_FAULT_ENV
from zeus_ros.bags.durable import DurableBagWriter
from zeus_ros.bags.recover import step_from_cdr
from zeus_ros.bags.schema import TOPIC_STATE, TOPIC_STEP
from zeus_ros.cli import recover


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_failed_flush_leaves_a_bag_zeus_recover_closes(
        storage: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    source = _write_synthetic(tmp_path / 'source', 12)
    from rosbags.rosbag2 import Reader

    with Reader(source) as reader:
        messages = [(c.topic, t, raw) for c, t, raw in reader.messages()
                    if c.topic in (TOPIC_STATE, TOPIC_STEP)]
    switch = tmp_path / 'fault'
    monkeypatch.setenv(WRITE_FAULT_ENV, str(switch))
    bag = tmp_path / 'bag'
    writer = DurableBagWriter(bag, storage=storage, pixels=False)  # type: ignore[arg-type]
    for topic, stamp, raw in messages[:12]:
        writer.write_serialized(topic, stamp, raw)
    writer.flush()  # steps 0-5 are on disk
    for topic, stamp, raw in messages[12:]:
        writer.write_serialized(topic, stamp, raw)
    switch.write_text('ENOSPC')
    with pytest.raises(OSError) as info:
        writer.flush()
    assert info.value.errno == errno.ENOSPC
    writer.abandon()  # writes nothing more, raises nothing
    switch.unlink()
    assert recover.main([str(bag)]) == 0
    with Reader(bag) as reader:
        kept = [step_from_cdr(raw) for c, _, raw in reader.messages() if c.topic == TOPIC_STEP]
    assert kept[:6] == list(range(6)), kept  # everything flushed before the failure
