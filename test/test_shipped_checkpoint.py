"""The checkpoint the demo ships: it loads, matches its card's task, and beats random play."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from zeus_ros.learning.inference import InferenceAgent
from zeus_ros.offline.evaluation.evaluate import evaluate_contexts

CHECKPOINT = Path(__file__).resolve().parents[1] / 'checkpoints' / 'cheetah_run_v0_zeus_state.pt'
VALUES = [{'torso_length': 0.75}, {'torso_length': 1.0}, {'torso_length': 1.15}]


@pytest.mark.slow
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


ROOT = Path(__file__).resolve().parents[1]
COMPARISON = ROOT / 'checkpoints' / 'comparison'


@pytest.mark.slow
def test_every_comparison_checkpoint_matches_its_card() -> None:
    """Each shipped comparison checkpoint is a deployment export whose card names its hash."""
    import hashlib

    from zeus_ros.learning.checkpoint import load_checkpoint

    paths = sorted(COMPARISON.glob('*/*.pt'))
    assert len(paths) >= 45, 'expected 5 tasks x 3 methods x 3 seeds at least'
    for path in paths:
        card = path.with_suffix('.md').read_text()
        assert hashlib.sha256(path.read_bytes()).hexdigest() in card, path
        loaded = load_checkpoint(path)
        # Cards written before the method registry call plain SAC on the true context `oracle`.
        method = 'oracle' if loaded.config.method == 'oracle_sac' else loaded.config.method
        assert loaded.deploy and loaded.spec.task in card and f'`{method}`' in card


@pytest.mark.slow
def test_zeus_eval_reproduces_the_results_table_from_a_shipped_checkpoint(tmp_path: Path) -> None:
    """`zeus eval` on a comparison checkpoint gives the return recorded in docs/results."""
    import csv

    import torch

    from zeus_ros.offline.evaluation.evaluate import evaluate

    torch.set_num_threads(1)
    result = evaluate(COMPARISON / 'cheetah_run_v0_10k' / 'zeus_s0.pt', split='train',
                      episodes=1, probe_steps=0, seed=100, out=tmp_path, progress=False,
                      diagnostics=False)
    with (ROOT / 'docs' / 'results' / 'cheetah_run_v0_10k' / 'runs.csv').open() as handle:
        recorded = next(row for row in csv.DictReader(handle) if row['method'] == 'zeus'
                        and row['seed'] == '0' and row['split'] == 'train')
    measured = result['summary'][0]['mean_return']
    # Same machine type: identical; another CPU's float rounding may move a 500-step rollout.
    assert measured == pytest.approx(float(recorded['mean_return']), rel=0.05)


@pytest.mark.slow
def test_an_issue10_checkpoint_reproduces_its_card(tmp_path: Path) -> None:
    """`zeus eval` on a shipped issue-10 export gives the train numbers of its card."""
    import re

    import torch

    from zeus_ros.offline.evaluation.evaluate import evaluate

    torch.set_num_threads(1)
    path = ROOT / 'checkpoints' / 'issue10' / 'scale_free_only' / 'cheetah_run_v1_10k'
    path = path / 'zeus_s0.pt'
    row = re.search(r'^\| train \| (\S+) \| \S+ \| \S+ \| \S+ \| \S+ \| (\S+) \| (\S+) \|$',
                    path.with_suffix('.md').read_text(), re.M)
    assert row, 'card without a train row'
    summary = evaluate(path, split='train', probe_steps=0, seed=100, out=tmp_path / 'eval',
                       progress=False)['summary'][0]
    assert summary['mean_return'] == pytest.approx(float(row[1]), abs=0.15)
    assert summary['sensitivity'] == pytest.approx(float(row[2]), abs=2e-3)
    assert summary['adaptation_value_mean'] == pytest.approx(float(row[3]), abs=0.15)
    # on the train values their mean is the split's mean: the same number, no second rollout
    assert summary['adaptation_value_train_mean'] == summary['adaptation_value_mean']
    assert np.isfinite(summary['adaptation_value_steady'])
