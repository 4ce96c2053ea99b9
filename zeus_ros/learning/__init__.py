"""The ZeUS learning core: encoders, context model, SAC and baselines (PyTorch, no ROS).

Public API (others code against these names):
  make_agent(config, spec) -> ZeusAgent; agent.update(batch, pair, step) -> metrics;
  agent.encode_context(...); agent.act(obs, context); save_checkpoint / load_checkpoint;
  InferenceAgent / ContextHistory for deployment; FrameStack for pixels; load_config for YAML.
"""

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
