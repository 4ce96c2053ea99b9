"""A method is one objective (learning/objectives/): a new one is a module plus a registry line.

The tiny objective below is the example: defined here, registered with one line, it builds
and trains end to end through the same agent as the shipped methods. No MuJoCo: the fast lane.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import pytest
import torch
import torch.nn.functional as F  # noqa: N812

from zeus_ros.learning import ZeusConfig, make_agent, resolve_config
from zeus_ros.learning.methods import METHOD_REGISTRY, METHODS, method_objective
from zeus_ros.learning.objectives import LossHost, PsiObjective, PsiStep
from zeus_ros.learning.synthetic import SyntheticSystem

torch.set_num_threads(1)
ROOT = Path(__file__).resolve().parents[1]


class RewardOnly(PsiObjective):
    """The example: psi(H) trained to predict the reward, nothing else."""

    name = 'reward_only'
    description = 'example: psi(H) trained by reward prediction'
    models = ('reward',)
    options = ('k', 'aggregation', 'context_dim', 'model_hidden_dim')

    def psi_loss(self, host: LossHost, step: PsiStep, metrics: dict[str, torch.Tensor]
                 ) -> torch.Tensor:
        """MSE of R(phi(o), a, psi(H)) against the reward."""
        predicted = host.modules['reward'](step.feat, step.action, step.psi)
        metrics['loss/reward'] = loss = F.mse_loss(predicted, step.batch.reward)
        return loss


@pytest.fixture
def registered(monkeypatch: pytest.MonkeyPatch) -> None:
    """RewardOnly in the registry for one test (the one line a new objective adds there)."""
    monkeypatch.setitem(METHOD_REGISTRY, RewardOnly.name, RewardOnly())


def _config(method: str, **changes: object) -> ZeusConfig:
    return ZeusConfig(**{'method': method, 'k': 3, 'alpha_psi': 1.0, 'hidden_dim': 32,
                         'model_hidden_dim': 32, 'context_hidden_dim': 32,
                         'encoder_hidden_dim': 32, 'transition_dim': 8, 'context_dim': 4,
                         'feature_dim': 16, 'batch_size': 8, 'device': 'cpu', **changes})


@pytest.mark.usefixtures('registered')
def test_a_new_objective_trains_end_to_end() -> None:
    """Registered with one line, the example builds what it declares and its loss falls."""
    system = SyntheticSystem(k=3)
    agent = make_agent(_config('reward_only'), system.spec())
    assert {'psi', 'reward'} <= set(agent.modules) and 'transition' not in agent.modules
    assert agent.context_dim == 4 and not agent.objective.needs_pair(agent.config)
    batch = system.sample(16)
    losses = [agent.update(batch, None, step)['loss/reward'] for step in range(15)]
    assert all(math.isfinite(v) for v in losses)
    assert losses[-1] < losses[0]
    context = agent.encode_context(batch.hist_obs[0], batch.hist_action[0],
                                   batch.hist_reward[0], batch.hist_next_obs[0],
                                   batch.hist_mask[0])
    assert context.shape == (4,)


def test_an_unregistered_objective_is_refused() -> None:
    """Without its registry line the method is unknown, and the error lists the methods."""
    with pytest.raises(ValueError, match='zeus_no_context_loss'):
        method_objective('reward_only')


@pytest.mark.parametrize('method', METHODS)
def test_every_registered_method_builds_and_updates(method: str) -> None:
    """Each shipped objective: its declared models exist, a pair only where it asks for one."""
    objective = method_objective(method)
    system = SyntheticSystem(k=3)
    agent = make_agent(_config(method), system.spec())
    assert agent.objective is objective
    assert ('psi' in agent.modules) == (objective.context_source == 'psi')
    assert all(name in agent.modules for name in objective.models)
    needs_pair = objective.needs_pair(agent.config)
    for step in range(2):
        pair = system.sample(8) if needs_pair else None
        metrics = agent.update(system.sample(8), pair, step)
        assert all(math.isfinite(v) for v in metrics.values())
    assert ('loss/context' in metrics) == needs_pair


def test_pinned_options_apply_through_resolve() -> None:
    """A method's `fixed` values win over the config (the ablation's alpha_psi = 0)."""
    for method in METHODS:
        pinned = method_objective(method).fixed
        resolved = resolve_config(ZeusConfig(method=method, alpha_psi=0.5), 'Synthetic-v0')
        assert resolved.alpha_psi == pinned.get('alpha_psi', 0.5), method


def test_objectives_list_only_config_options() -> None:
    """Every option an objective says it reads is a config field (cards print them)."""
    fields = set(ZeusConfig().to_dict())
    for method in METHODS:
        unknown = set(method_objective(method).options) - fields
        assert not unknown, (method, unknown)


NAMES_NOT_LOGIC = {
    'zeus_ros/learning/config.py': "stored configs from before the registry: old 'oracle' is "
                                   "today's 'oracle_sac' (a rename, read once at load)",
    'zeus_ros/system/launch_defaults.py': "zoo file naming: a family's checkpoint is the zeus "
                                          'one, the others sit beside it as <method>.pt',
}
"""Modules where a method name is compared as a name (file names, renames), not as logic."""


def test_no_method_name_comparisons_outside_the_objectives() -> None:
    """Code asks the objective, it does not compare a method name with a literal."""
    allowed = (ROOT / 'zeus_ros' / 'learning' / 'objectives', ROOT / 'zeus_ros' / 'learning'
               / 'methods.py')
    found = []
    for package in ('zeus_ros', 'sim_bridge'):
        for path in (ROOT / package).rglob('*.py'):
            if any(path == a or a in path.parents for a in allowed) or \
                    str(path.relative_to(ROOT)) in NAMES_NOT_LOGIC:
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
                if isinstance(node, ast.Compare):
                    for side in (node.left, *node.comparators):
                        for leaf in ast.walk(side):
                            if isinstance(leaf, ast.Constant) and leaf.value in METHODS:
                                found.append(f'{path.relative_to(ROOT)}:{node.lineno}')
    assert found == []
