"""Ingest of bags other software closed: complete is not torn, and a QoS mismatch is named.

Real files: a bag written by the project's writer, then rewritten as another writer closes a
file (no summary section, no metadata record, no metadata.yaml) or with metadata.yaml's QoS
edited; a torn file is what a kill leaves (the chunks flushed so far, no footer).
"""

from __future__ import annotations

from pathlib import Path
import shutil
import struct

import pytest
from ruamel.yaml import YAML
from test_bags import _write_synthetic

from zeus_ros.bags.errors import BagError, IngestError
from zeus_ros.bags.mcap_file import MAGIC, closed_by_writer
from zeus_ros.bags.recover import bag_state
from zeus_ros.bags.schema import TOPIC_STATE, TOPIC_STEP
from zeus_ros.offline.data.ingest import ingest_bags


def _records(data: bytes) -> list[tuple[int, int, int]]:
    """(opcode, start, end) of the top-level records of an mcap file."""
    found, pos = [], len(MAGIC)
    while pos < len(data) - len(MAGIC):
        opcode, (length,) = data[pos], struct.unpack_from('<Q', data, pos + 1)
        found.append((opcode, pos, pos + 9 + length))
        pos += 9 + length
        if opcode == 0x02:
            break
    return found


def close_like_another_writer(mcap: Path) -> None:
    """Rewrite `mcap` complete but closed differently (the mcap spec allows all of it).

    The data section without rosbag2's metadata record, no summary, a footer with
    summary_start 0.
    """
    data = mcap.read_bytes()
    out = bytearray(MAGIC)
    for opcode, start, end in _records(data):
        if opcode == 0x0C:  # rosbag2's metadata record
            continue
        out += data[start:end]
        if opcode == 0x0F:  # data end: the summary would follow
            break
    out += bytes([0x02]) + struct.pack('<QQQI', 20, 0, 0, 0) + MAGIC
    mcap.write_bytes(bytes(out))


def cut_like_a_kill(mcap: Path) -> None:
    """Keep what a killed recorder left: everything up to its last flushed chunk, no footer."""
    data = mcap.read_bytes()
    end = max(e for opcode, _, e in _records(data) if opcode in (0x06, 0x07))
    mcap.write_bytes(data[:end])


def test_a_complete_mcap_of_another_writer_is_read_not_called_torn(tmp_path: Path) -> None:
    """No summary, no metadata record, no metadata.yaml: read as it is, no crash named."""
    bag = _write_synthetic(tmp_path / 'other', 12)
    mcap = bag / 'other.mcap'
    close_like_another_writer(mcap)
    (bag / 'metadata.yaml').unlink()
    assert closed_by_writer(mcap)
    assert bag_state(bag) is None  # zeus train says nothing of a crash
    data = ingest_bags(bag)
    assert data.num_transitions == 10 and not data.report.issues


def test_a_torn_mcap_is_told_apart_and_named_with_zeus_recover(tmp_path: Path) -> None:
    bag = _write_synthetic(tmp_path / 'torn', 12)
    cut_like_a_kill(bag / 'torn.mcap')
    (bag / 'metadata.yaml').unlink()
    assert not closed_by_writer(bag / 'torn.mcap')
    assert bag_state(bag) == 'unfinished'
    with pytest.raises(BagError, match='no complete file') as info:
        ingest_bags(bag)
    assert f'zeus recover {bag}' in str(info.value)


def _edit_qos(bag: Path, topics: tuple[str, ...]) -> None:
    """metadata.yaml offers best effort on `topics`; the file recorded them reliable."""
    yaml = YAML(typ='safe')
    yaml.default_flow_style = False
    meta = bag / 'metadata.yaml'
    info = yaml.load(meta.read_text())
    for entry in info['rosbag2_bagfile_information']['topics_with_message_count']:
        if entry['topic_metadata']['name'] in topics:
            for profile in entry['topic_metadata']['offered_qos_profiles']:
                profile['reliability'] = 'best_effort'
    with meta.open('w') as handle:
        yaml.dump(info, handle)


def test_a_qos_mismatch_is_named_and_the_messages_still_read(tmp_path: Path) -> None:
    """Without --strict: one 'qos' issue per topic naming both QoS; every message is read.

    (Before, rosbags paired metadata and file by QoS and left those topics unread.)
    """
    bag = _write_synthetic(tmp_path / 'qos', 12)
    _edit_qos(bag, (TOPIC_STEP, TOPIC_STATE))
    with pytest.warns(UserWarning, match='metadata.yaml offers QoS best_effort'):
        data = ingest_bags(bag)
    qos = [i for i in data.report.issues if i.kind == 'qos']
    assert sorted(i.topic for i in qos) == sorted([TOPIC_STEP, TOPIC_STATE])
    assert 'the file recorded reliable' in qos[0].detail
    assert data.num_transitions == 10
    with pytest.raises(IngestError, match='qos'):
        ingest_bags(bag, strict=True)
    shutil.rmtree(bag)


def test_the_file_qos_comes_from_the_open_reader_as_the_file_holds_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The QoS the open reader parsed from the file (no second parse) equal the file's own."""
    from rosbags.rosbag2 import Reader

    from zeus_ros.bags.mcap_file import channel_qos, qos_text
    from zeus_ros.offline.data import ingest

    bag = _write_synthetic(tmp_path / 'qos', 4)
    _edit_qos(bag, (TOPIC_STEP,))
    mcap = next(bag.glob('*.mcap'))
    with monkeypatch.context() as patch, Reader(bag) as reader:
        patch.setattr(ingest, 'channel_qos', None)  # not parsed again
        ours = ingest._file_qos(reader, mcap)
    assert {t: qos_text(q) for t, q in ours.items()} == \
        {t: qos_text(q) for t, q in channel_qos(mcap).items()}
    assert 'reliable' in qos_text(ours[TOPIC_STEP])
