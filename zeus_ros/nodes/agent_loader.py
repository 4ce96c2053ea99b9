"""Load the checkpoint a node runs, with the node's name in every error.

The file is read once: its bytes are hashed and decoded from memory by learning/ (the networks
and, from the same payload, the context read-out and novelty monitor), so what a node says it
runs is what it loaded. A relative path is found by launch_defaults.resolve_path, the one
resolver `zeus launch` uses too (next to the params file when there is one, then the package
share, then the working directory).

A node says exactly what it loaded (absolute path and sha256), at start and on a live
redeploy, and the estimator stamps every estimate with that sha256: the policy acts only on
estimates of its own checkpoint, so a half-done redeploy never pairs mismatched networks.
That same digest is compared with the file's recorded sha256 (card, sidecar, zoo index:
zeus_ros/integrity.py): a node given a changed zoo file exits 2, a live change to one is refused.

Nodes of one process (zeus launch --single-process) that load the same file share one
InferenceAgent: one copy of the networks, and the policy acts on the phi of the observation the
estimator has just encoded instead of encoding it again (InferenceAgent reuse_features).
"""

from __future__ import annotations

from collections.abc import Mapping
import contextlib
import ctypes
from dataclasses import dataclass
import hashlib
from pathlib import Path
from typing import Any
import weakref

import torch

from zeus_ros.learning.checkpoint import CheckpointError, verify_checkpoint
from zeus_ros.learning.inference import InferenceAgent
from zeus_ros.learning.readout import ContextReadout, NoveltyMonitor, monitors_from_extra
from zeus_ros.system.launch_defaults import resolve_path

__all__ = ['LoadedAgent', 'check_swappable', 'load_inference_agent']

_SHARED: weakref.WeakValueDictionary[tuple[str, str, str], InferenceAgent] = \
    weakref.WeakValueDictionary()
"""Agents of this process by (sha256, device, expected task), alive while a node holds them."""


@dataclass(frozen=True)
class LoadedAgent:
    """An agent with the identity of the file it came from."""

    agent: InferenceAgent
    path: Path
    """Absolute path of the checkpoint file."""
    sha256: str
    """Hex digest of the file's bytes, as they were read for loading."""
    readout: ContextReadout | None = None
    """The checkpoint's calibrated context read-out (psi -> context units), if it holds one."""
    novelty: NoveltyMonitor | None = None
    """The checkpoint's context novelty monitor (distance from the training contexts)."""

    def describe(self) -> str:
        """What a log line says about it."""
        return f'{self.path} (sha256 {self.sha256})'


def load_inference_agent(node_name: str, params: Mapping[str, Any]) -> LoadedAgent:
    """InferenceAgent from params checkpoint/task/device/torch_threads; ValueError if unusable.

    A relative checkpoint is looked up in the package share (where the shipped checkpoints
    are installed), then in the working directory (resolve_path). Inference on these small networks
    gains nothing from intra-op threads, and three node processes on a few cores would
    oversubscribe them, so `torch_threads` defaults to 1 (which also keeps results
    bit-identical with the in-process tools).
    """
    if params['torch_threads'] < 1:
        raise ValueError(f'{node_name}: parameter torch_threads must be >= 1')
    torch.set_num_threads(int(params['torch_threads']))
    path = resolve_path(str(params['checkpoint']), None, f'{node_name}: parameter checkpoint')
    try:
        data = path.read_bytes()
    except OSError as error:
        raise ValueError(f'{node_name}: checkpoint {path}: {error.strerror or error}') from error
    sha256 = hashlib.sha256(data).hexdigest()
    key = (sha256, str(params['device']), str(params['task']))
    agent = _SHARED.get(key)
    fresh = agent is None
    try:
        if agent is None:  # load_checkpoint checks the recorded sha256 against this digest
            agent = InferenceAgent.from_checkpoint(
                path, expect_task=params['task'] or None, device=params['device'],
                reuse_features=True, data=data, sha256=sha256)
        else:  # the same bytes, maybe under another name: checked as load_checkpoint would
            verify_checkpoint(path, data, sha256=sha256)
    except CheckpointError as error:
        raise ValueError(f'{node_name}: {error}') from error
    if fresh:
        agent.drop_training_modules()
        _release_freed_memory()
        _SHARED[key] = agent
    try:
        readout, novelty = monitors_from_extra(agent.extra, agent.context_dim)
    except ValueError as error:
        raise ValueError(f'{node_name}: checkpoint {path}: {error}') from error
    return LoadedAgent(agent, path, sha256, readout, novelty)


def _release_freed_memory() -> None:
    """Hand freed heap pages back to the system: glibc keeps them (elsewhere nothing happens)."""
    with contextlib.suppress(AttributeError, OSError):
        ctypes.CDLL(None).malloc_trim(0)


def check_swappable(node_name: str, old: InferenceAgent, new: InferenceAgent) -> None:
    """Raise ValueError unless `new` can replace `old` without restarting the node.

    Observations, actions and subscriptions were set up for `old`: the task, observation kind
    and shape, action size and the need for the true context must stay the same.
    """
    same = {
        'task': (old.task, new.task),
        'observation kind': (old.obs_kind, new.obs_kind),
        'observation shape': (tuple(old.obs_shape), tuple(new.obs_shape)),
        'action size': (old.action_dim, new.action_dim),
        'use of the true context': (old.needs_true_context, new.needs_true_context),
    }
    for what, (before, after) in same.items():
        if before != after:
            raise ValueError(f'{node_name}: the new checkpoint changes the {what} ({before} -> '
                             f'{after}); restart the node to load it')
