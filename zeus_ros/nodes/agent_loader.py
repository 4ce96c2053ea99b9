"""Load the checkpoint a node runs, with the node's name in every error."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch

from zeus_ros.learning.checkpoint import CheckpointError
from zeus_ros.learning.inference import InferenceAgent

__all__ = ['load_inference_agent']


def load_inference_agent(node_name: str, params: Mapping[str, Any]) -> InferenceAgent:
    """InferenceAgent from params checkpoint/task/device/torch_threads; ValueError if unusable.

    Inference on these small networks gains nothing from intra-op threads, and three node
    processes on a few cores would oversubscribe them, so `torch_threads` defaults to 1 (which
    also keeps results bit-identical with the in-process tools).
    """
    if params['torch_threads'] < 1:
        raise ValueError(f'{node_name}: parameter torch_threads must be >= 1')
    torch.set_num_threads(int(params['torch_threads']))
    try:
        return InferenceAgent.from_checkpoint(
            params['checkpoint'], expect_task=params['task'] or None, device=params['device'])
    except CheckpointError as error:
        raise ValueError(f'{node_name}: {error}') from error
