"""The tiny training configs of the tests: one definition, each test file's variant beside it.

Real training on networks small enough that a test trains in seconds; a test file changes
only what it is about (update counts, intervals), so every training test runs the same shapes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import pytest
import yaml

TINY: dict[str, Any] = {
    'method': 'zeus', 'obs_kind': 'state', 'k': 5, 'context_dim': 4, 'transition_dim': 16,
    'context_hidden_dim': 32, 'feature_dim': 16, 'encoder_hidden_dim': 64, 'hidden_dim': 64,
    'model_hidden_dim': 64, 'batch_size': 32, 'num_updates': 40, 'eval_interval': 1000,
    'eval_episodes': 1, 'checkpoint_interval': 1000, 'log_interval': 10, 'device': 'cpu',
}
"""Small networks: a few hundred updates take seconds (sweep trials, train/eval tests)."""

MINIMAL: dict[str, Any] = TINY | {
    'k': 3, 'transition_dim': 8, 'context_hidden_dim': 16, 'feature_dim': 8,
    'encoder_hidden_dim': 32, 'hidden_dim': 32, 'model_hidden_dim': 32, 'num_updates': 6,
    'checkpoint_interval': 2, 'log_interval': 2,
}
"""The smallest networks, checkpointing every 2 updates: the fault tests' handful of updates."""


def write_config(path: Path, config: Mapping[str, Any]) -> Path:
    """`config` as the YAML file `zeus train --config` reads; returns `path`."""
    path.write_text(yaml.safe_dump(dict(config)))
    return path


def config_fixture(config: Mapping[str, Any]) -> Callable[..., Path]:
    """A module-scoped `tiny_config` fixture: `config` written once as tiny.yaml."""

    @pytest.fixture(scope='module')
    def tiny_config(tmp_path_factory: pytest.TempPathFactory) -> Path:
        return write_config(tmp_path_factory.mktemp('config') / 'tiny.yaml', config)

    return tiny_config
