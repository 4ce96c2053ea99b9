"""The atomic pair swap: estimator and policy move to one checkpoint with no mismatched step.

The estimator stamps every estimate with its checkpoint's sha256 and the policy acts only on
estimates of its own checkpoint (policy_node.py). Setting the two `checkpoint` parameters one
after the other leaves a window in which the policy refuses estimates (counted `mismatched`,
safe actions). The swap here closes it: the policy first *stages* the new checkpoint (loaded,
checked, not yet used: policy ~/stage_checkpoint), then the estimator switches, and the policy
switches at the first estimate stamped with the staged sha256, on that same step. Every step is
acted on by a matched pair, old or new. Used by continual_trainer's ~/swap_checkpoint.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
import re
from typing import Any

from rclpy.node import Node
from rclpy.parameter import Parameter

from zeus_ros.system.launch_defaults import resolve_path

SHA256 = re.compile(r'[0-9a-f]{64}')
ESTIMATOR, POLICY = 'context_estimator', 'policy'
"""The pair, by name relative to the caller's namespace."""


def checked_file(checkpoint: str, expect_sha256: str) -> tuple[Path, str]:
    """The checkpoint's path and sha256; ValueError (one line) for a file the pair must not get."""
    if not checkpoint.strip():
        raise ValueError('no checkpoint given')
    expect = expect_sha256.strip().lower()
    if expect and not SHA256.fullmatch(expect):
        raise ValueError(f'expect_sha256 {expect_sha256!r} is not 64 hex digits')
    path = resolve_path(checkpoint, None, 'checkpoint')
    try:
        sha256 = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as error:
        raise ValueError(f'checkpoint {path}: {error.strerror or error}') from None
    if expect and sha256 != expect:
        raise ValueError(f'checkpoint {path} has sha256 {sha256[:12]}, expected '
                         f'{expect[:12]}: refused (the file changed?)')
    return path, sha256


class PairSwapper:
    """Swaps the pair of the caller's namespace; one swap at a time."""

    def __init__(self, node: Node) -> None:
        """Clients of the policy's staging service and the estimator's parameters."""
        from rclpy.callback_groups import ReentrantCallbackGroup
        from rclpy.parameter_client import AsyncParameterClient
        from zeus_msgs.srv import SwapCheckpoint

        self.node = node
        # Their answers must get through while the swap service's own callback awaits them.
        group = ReentrantCallbackGroup()
        self.stage = node.create_client(SwapCheckpoint, f'{POLICY}/stage_checkpoint',
                                        callback_group=group)
        self.estimator = AsyncParameterClient(node, ESTIMATOR, callback_group=group)
        self.busy = False
        self.swapped_to: Path | None = None
        """The checkpoint of the last swap made."""

    async def swap(self, checkpoint: str, expect_sha256: str) -> tuple[str, str]:
        """Stage on the policy, then switch the estimator; (what was done, sha256) or ValueError.

        A refusal by the estimator unstages the policy: the pair runs on unchanged.
        """
        if self.busy:
            raise ValueError('a swap is under way: try again when it answered')
        path, sha256 = checked_file(checkpoint, expect_sha256)
        if not self.stage.service_is_ready():
            raise ValueError(f'{self.stage.srv_name} is not offered: is the policy running?')
        if not self.estimator.services_are_ready():
            raise ValueError(f'{ESTIMATOR} offers no parameter services: is it running?')
        self.busy = True
        try:
            staged = await self._stage(str(path), sha256)
            if not staged.success:
                raise ValueError(f'the policy refused it: {staged.message}')
            result = await self.estimator.set_parameters(
                [Parameter('checkpoint', value=str(path))])
            if result is None or not all(r.successful for r in result.results):
                await self._stage('', '')
                why = result.results[0].reason if result is not None else 'no answer'
                raise ValueError(f'{ESTIMATOR} refused it ({why}); the policy stays on its '
                                 'checkpoint')
        finally:
            self.busy = False
        self.swapped_to = path
        return (f'swapped to {path} (sha256 {sha256[:12]}): the estimator runs it, the policy '
                'follows at its first estimate', sha256)

    async def _stage(self, checkpoint: str, sha256: str) -> Any:
        from zeus_msgs.srv import SwapCheckpoint

        request = SwapCheckpoint.Request(checkpoint=checkpoint, expect_sha256=sha256)
        return await self.stage.call_async(request)
