"""The policy node's context_lag rule, on a real PolicyNode driven message by message.

The live tests check that lag 1 acts as `zeus collect --context-lag 1` does from step 0; these
check what they cannot reach: a policy that joins an episode already running, and one that
was just redeployed, must not wait for contexts from before it had any (they never come).
"""

from __future__ import annotations

from collections.abc import Iterator
import contextlib
from pathlib import Path
import time
from typing import Any

import numpy as np
import pytest

from live_fixtures import tiny_checkpoint
from ros_harness import fresh_domain_id, require_ros, ros_context

pytestmark = pytest.mark.ros


@contextlib.contextmanager
def policy_node(checkpoint: Path, lag: int) -> Iterator[tuple[Any, list[tuple[int, int, str]]]]:
    """A PolicyNode on its own context; yields it and the (step, context step, kind) it acted."""
    require_ros()
    import torch

    from zeus_ros.nodes.policy_node import PolicyNode

    threads = torch.get_num_threads()  # the node sets torch_threads in this test process
    with ros_context(fresh_domain_id()) as context:
        node = PolicyNode(context=context, cli_args=[
            '--ros-args', '-p', f'checkpoint:={checkpoint}', '-p', f'context_lag:={lag}',
            '-p', 'context_deadline:=30.0'])
        acted: list[tuple[int, int, str]] = []
        # Each context's data holds its step, so the action's context names the step it came
        # from.
        node._act = lambda step, _feedback, _obs, ctx, kind: acted.append((step, int(ctx[0]),
                                                                            kind))
        try:
            yield node, acted
        finally:
            node.destroy_node()
            torch.set_num_threads(threads)


def observe(node: Any, step: int, first: bool = False) -> None:
    """Hand the node observation `step` as its step assembler would."""
    from zeus_msgs.msg import StepFeedback

    from zeus_ros.nodes.assembler import StepParts

    feedback = StepFeedback(step=step, first=first)
    state = np.full(node.agent.obs_shape, 0.1 * step, np.float32)
    node._on_observation(StepParts(step, {'feedback': feedback, 'obs': (time.monotonic(), state)}))


def estimate(node: Any, step: int) -> None:
    """Hand the node the estimator's context of `step` (every value = the step)."""
    from zeus_msgs.msg import ContextEstimate

    msg = ContextEstimate(step=step, checkpoint_sha256=node.loaded.sha256)
    msg.data = [float(step)] * node.agent.context_dim
    node._on_context(msg)


def test_a_policy_joining_mid_episode_waits_for_its_first_context_then_lags(
        tmp_path: Path) -> None:
    """Lag 2 from step 50: contexts 48 and 49 never come, so 50 waits for 50, not 48."""
    with policy_node(tiny_checkpoint(tmp_path / 'tiny.pt'), lag=2) as (node, acted):
        observe(node, 50)
        assert acted == []  # waiting: no context yet
        estimate(node, 50)
        observe(node, 51)  # wants 49: none before 50, so 50
        estimate(node, 51)
        observe(node, 52)  # wants 50
        estimate(node, 52)
        observe(node, 53)  # wants 51
        assert acted == [(50, 50, 'fresh'), (51, 50, 'fresh'), (52, 50, 'fresh'),
                         (53, 51, 'fresh')]


def test_after_a_redeploy_the_lag_starts_again_from_the_new_pair_s_first_context(
        tmp_path: Path) -> None:
    """The old pair's contexts are dropped at a redeploy: no stale step waiting for them."""
    checkpoint = tiny_checkpoint(tmp_path / 'tiny.pt')
    with policy_node(checkpoint, lag=1) as (node, acted):
        estimate(node, 0)
        observe(node, 0, first=True)
        estimate(node, 1)
        observe(node, 1)
        node._pending = node.loaded  # what a live `checkpoint` change has loaded
        node._apply_live({'checkpoint': str(checkpoint)})
        observe(node, 2)  # context 1 was the old pair's: wait for context 2
        assert acted[-1] == (1, 0, 'fresh')
        estimate(node, 2)
        observe(node, 3)
        assert acted == [(0, 0, 'fresh'), (1, 0, 'fresh'), (2, 2, 'fresh'), (3, 2, 'fresh')]
        assert node.counts['stale'] == 0
