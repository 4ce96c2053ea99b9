"""Batch CDR decoding (ingest's fast path) gives exactly what rosbags gives, message by message."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from zeus_ros.bags.cdr_columns import FIELDS, decode_messages
from zeus_ros.bags.schema import StepFeedbackFields, codec


def _messages(kind: str, count: int) -> list[Any]:
    """`count` messages of one type: varying steps, values, lengths and frame ids."""
    cdc = codec()
    rng = np.random.default_rng(0)
    out = []
    for k in range(count):
        stamp = 1_000_000_000 * k + 7 * k
        if kind == 'zeus_msgs/msg/StateVector':
            msg = cdc.state(k, stamp, rng.normal(size=17 if k % 5 else 3))
        elif kind == 'zeus_msgs/msg/Action':
            msg = cdc.action(k, stamp, rng.normal(size=6))
        elif kind == 'zeus_msgs/msg/ContextTruth':
            names = ['torso_length'] if k % 4 else ['friction', 'mass']
            msg = cdc.truth(k, stamp, names, rng.normal(size=len(names)), segment=k // 3)
        else:
            first = k % 7 == 0
            msg = cdc.feedback(k, stamp, StepFeedbackFields(
                episode=k // 7, episode_step=k % 7, first=first, last=k % 7 == 6,
                reward=float(rng.normal()), applied_action=np.zeros(0) if first else
                rng.normal(size=6), action_status=0 if first else 1 + k % 3,
                task='Cheetah-Run-v0' if k % 3 else 'Walker-Walk-v0'))
        if k % 6 == 5:  # another frame_id shifts every later field
            msg.header.frame_id = 'base_link'
        out.append(msg)
    return out


@pytest.mark.parametrize('msgtype', sorted(FIELDS))
def test_batches_decode_as_rosbags_does(msgtype: str) -> None:
    """Every field and the stamp equal rosbags' decoding; few messages take the slow path."""
    cdc = codec()
    raws = [cdc.serialize(m) for m in _messages(msgtype, 60)]
    raws.append(bytes(cdc.store.serialize_cdr(cdc.deserialize(raws[1], msgtype), msgtype,
                                               little_endian=False)))  # big endian: slow path
    slow: list[int] = []

    def one(i: int) -> Any:
        slow.append(i)
        return cdc.deserialize(raws[i], msgtype)

    decoded = decode_messages(raws, msgtype, one)
    for raw, ours in zip(raws, decoded, strict=True):
        theirs = cdc.deserialize(raw, msgtype)
        assert ours.stamp_ns == theirs.header.stamp.sec * 10**9 + theirs.header.stamp.nanosec
        for name, _kind in FIELDS[msgtype]:
            mine, ref = getattr(ours, name), getattr(theirs, name)
            if isinstance(ref, np.ndarray):
                assert mine.dtype == ref.dtype and np.array_equal(mine, ref), name
            else:
                assert type(mine) is type(ref) and mine == ref, name
    assert len(raws) - 1 in slow and len(slow) < 16, slow  # first of each group + big endian


def test_a_corrupt_message_fails_through_the_fallback() -> None:
    """A truncated message is decoded by the fallback, whose error reaches the caller."""
    cdc = codec()
    raws = [cdc.serialize(m) for m in _messages('zeus_msgs/msg/StateVector', 4)]
    raws[2] = raws[2][:-9]

    def one(i: int) -> Any:
        if i == 2:
            raise ValueError('truncated')
        return cdc.deserialize(raws[i], 'zeus_msgs/msg/StateVector')

    with pytest.raises(ValueError, match='truncated'):
        decode_messages(raws, 'zeus_msgs/msg/StateVector', one)
