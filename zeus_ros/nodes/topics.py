"""The step protocol's topic names and QoS: one table every node publishes and subscribes by.

Kept apart from how a node process runs (spin.py) so that a tool that only names topics (the
inspector, the recorder's offered QoS) reads them without the executor and signal machinery.
"""

from __future__ import annotations

from rclpy.qos import (
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

__all__ = [
    'STEP_BACKLOG',
    'TOPICS',
    'action_qos',
    'image_qos',
    'publisher_qos',
    'step_qos',
]


class TOPICS:
    """Topic names of the step protocol (DESIGN.md section 1); one place for all nodes.

    The zeus topics are relative, so `__ns:=/robot1` moves a whole system and `-r` remaps them;
    /clock and /diagnostics stay absolute, as ROS convention wants (one clock, one aggregator).
    """

    STATE = 'zeus/observation/state'
    IMAGE = 'zeus/observation/image'
    STEP = 'zeus/step'
    CONTEXT_TRUTH = 'zeus/context_truth'
    CONTEXT = 'zeus/context'
    CONTEXT_READOUT = 'zeus/context_readout'
    """ContextTruth-typed: the estimate in the context's units (the checkpoint's read-out)."""
    CONTEXT_NOVELTY = 'zeus/context_novelty'
    """ContextTruth-typed: names novelty, threshold, novel (1.0 outside the training contexts)."""
    ACTION = 'zeus/action'
    CLOCK = '/clock'
    DIAGNOSTICS = '/diagnostics'


def step_qos(depth: int = 10) -> QoSProfile:
    """Reliable keep-last: in lockstep no step may silently vanish (a loss shows as a gap)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE
    )


STEP_BACKLOG = 1000
"""History depth of a lockstep publisher. A reliable reader that misses messages (a recorder
starved of CPU on a busy machine: its transport queue overflows) gets them resent when DDS
notices the loss, which can take a good part of a second; at a few hundred steps/s a history
of 10 was overwritten by then and the bag had gaps. The recorder's reader history is as deep
(RECORD_DEPTH). Small messages: a few hundred KiB per topic at most."""


def publisher_qos(mode: str) -> QoSProfile:
    """Step-protocol publishers: reliable, with a STEP_BACKLOG-deep history in lockstep."""
    return step_qos(STEP_BACKLOG) if mode == 'lockstep' else step_qos()


def image_qos(mode: str) -> QoSProfile:
    """Frames: reliable in lockstep (every step counts); sensor-data (best effort) in realtime."""
    return step_qos() if mode == 'lockstep' else qos_profile_sensor_data


def action_qos(mode: str) -> QoSProfile:
    """Actions: reliable; in realtime only the newest matters (depth 1, zero-order hold)."""
    return publisher_qos(mode) if mode == 'lockstep' else step_qos(depth=1)
