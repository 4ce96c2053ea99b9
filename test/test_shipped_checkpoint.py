"""The checkpoint the demo ships: it loads, matches its card's task, and beats random play."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from zeus_ros.learning.inference import InferenceAgent
from zeus_ros.offline.evaluate import evaluate_contexts

CHECKPOINT = Path(__file__).resolve().parents[1] / 'checkpoints' / 'cheetah_run_v0_zeus_state.pt'
VALUES = [{'torso_length': 0.75}, {'torso_length': 1.0}, {'torso_length': 1.15}]


def test_shipped_checkpoint_scores_well_above_random_on_train_contexts() -> None:
    """One deterministic episode per train value: at least 10x the uniform random policy."""
    import torch

    torch.set_num_threads(1)
    agent = InferenceAgent.from_checkpoint(CHECKPOINT, expect_task='Cheetah-Run-v0',
                                           expect_obs_kind='state')
    assert (agent.method, agent.k, agent.context_dim) == ('zeus', 5, 10)
    trained = [row['return'] for row in evaluate_contexts(agent, VALUES, progress=False)]
    random = [row['return'] for row in evaluate_contexts(
        None, VALUES, task_name='Cheetah-Run-v0', progress=False)]
    assert np.mean(trained) > 10 * np.mean(random), (trained, random)
    assert min(trained) > 400, trained
