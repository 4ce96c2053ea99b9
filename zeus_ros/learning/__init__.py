"""The ZeUS learning core: encoders, context model, SAC and baselines (PyTorch, no ROS).

Public API (others code against these names):
  make_agent(config, spec) -> ZeusAgent; agent.update(batch, pair, step) -> metrics;
  agent.encode_context(...); agent.act(obs, context); save_checkpoint / load_checkpoint;
  InferenceAgent / ContextHistory for deployment; FrameStack for pixels; load_config for YAML.

The names are imported on first use (PEP 562), not with the package: `zeus_ros.learning.errors`
or `.method_names` must not pull in torch, so that every `zeus <command> --help` and argument
error answers at once (issue 52).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from zeus_ros.learning.agent import PSI_METHODS, ZeusAgent, make_agent
    from zeus_ros.learning.batch import HistoryBatch
    from zeus_ros.learning.checkpoint import (
        FORMAT_VERSION,
        LoadedCheckpoint,
        load_checkpoint,
        save_checkpoint,
    )
    from zeus_ros.learning.config import (
        AGGREGATIONS,
        METHODS,
        ZeusConfig,
        config_from_dict,
        load_config,
        resolve_config,
    )
    from zeus_ros.learning.errors import CheckpointError, ConfigError
    from zeus_ros.learning.frames import FrameStack
    from zeus_ros.learning.inference import ContextHistory, HistoryArrays, InferenceAgent
    from zeus_ros.learning.spec import AgentSpec

_HOMES: dict[str, str] = {
    'PSI_METHODS': 'agent', 'ZeusAgent': 'agent', 'make_agent': 'agent',
    'HistoryBatch': 'batch',
    'FORMAT_VERSION': 'checkpoint', 'LoadedCheckpoint': 'checkpoint',
    'load_checkpoint': 'checkpoint', 'save_checkpoint': 'checkpoint',
    'AGGREGATIONS': 'config', 'METHODS': 'config', 'ZeusConfig': 'config',
    'config_from_dict': 'config', 'load_config': 'config', 'resolve_config': 'config',
    'CheckpointError': 'errors', 'ConfigError': 'errors',
    'FrameStack': 'frames',
    'ContextHistory': 'inference', 'HistoryArrays': 'inference', 'InferenceAgent': 'inference',
    'AgentSpec': 'spec',
}
"""Public name -> the submodule that defines it."""

__all__ = [
    'AGGREGATIONS',
    'FORMAT_VERSION',
    'METHODS',
    'PSI_METHODS',
    'AgentSpec',
    'CheckpointError',
    'ConfigError',
    'ContextHistory',
    'FrameStack',
    'HistoryArrays',
    'HistoryBatch',
    'InferenceAgent',
    'LoadedCheckpoint',
    'ZeusAgent',
    'ZeusConfig',
    'config_from_dict',
    'load_checkpoint',
    'load_config',
    'make_agent',
    'resolve_config',
    'save_checkpoint',
]


def __getattr__(name: str) -> Any:
    """Import a public name's submodule on first use (torch only when a torch name is asked)."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(f'{__name__}.{home}'), name)
    globals()[name] = value
    return value
