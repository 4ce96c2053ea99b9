"""Training, evaluation, probe and loop on real collected Cheetah-Run-v0 bags (CPU, short).

Cheetah-Run-v0's episodes are cut from 500 to EPISODE steps in this module (its evaluations roll
out every policy on every value: the step count is what these tests cost, not what they check).
"""

from __future__ import annotations

from collections.abc import Iterator
import itertools
import json
from pathlib import Path
import shutil
from typing import Any

import numpy as np
import pytest
import torch
import yaml

from zeus_ros.cli import collect
from zeus_ros.learning.checkpoint import load_checkpoint
from zeus_ros.learning.config import load_config
from zeus_ros.offline.evaluation.metrics import read_csv
from zeus_ros.offline.runs import read_state
from zeus_ros.offline.training.train import TrainError, train

from tiny_config import TINY, config_fixture

TASK = 'Cheetah-Run-v0'
CONFIG = TINY | {'batch_size': 64, 'num_updates': 240, 'eval_interval': 240, 'eval_episodes': 2,
                 'checkpoint_interval': 100, 'log_interval': 20}

EPISODE = 100
"""Steps per Cheetah-Run-v0 episode in this module (the task's own: 500)."""
EVERY = 22
"""--switch-every of the evaluations: 4 mid-episode switches, the last 12 steps from the end."""

torch.set_num_threads(1)


@pytest.fixture(scope='module', autouse=True)
def short_episodes() -> Iterator[None]:
    """Cheetah-Run-v0 episodes of EPISODE steps for every test of this module, in process."""
    from sim_bridge.registry import task_class

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(task_class(TASK), 'episode_length', EPISODE)
        yield


@pytest.fixture(scope='module')
def bags(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """600 random-policy steps with the torso length switching every 100 steps."""
    out = tmp_path_factory.mktemp('bags')
    code = collect.main(['--task', TASK, '--steps', '600', '--schedule',
                         'switch:values=train,every=100', '--out', str(out), '--no-progress'])
    assert code == 0
    return out


tiny_config = config_fixture(CONFIG)


@pytest.fixture(scope='module')
def trained(bags: Path, tiny_config: Path, tmp_path_factory: pytest.TempPathFactory) -> Any:
    """One short zeus run with one periodic evaluation at its end."""
    out = tmp_path_factory.mktemp('run') / 'zeus'
    return train([bags], load_config(tiny_config), out, progress=False, log=lambda _m: None)


def _mean(rows: list[dict[str, Any]], key: str) -> float:
    return float(np.mean([row[key] for row in rows]))


@pytest.mark.slow
def test_model_losses_fall_and_the_run_writes_its_files(trained: Any) -> None:
    """Dynamics and reward losses drop; checkpoints, CSV and PNGs are written."""
    rows = trained.log
    assert trained.step == 240 and [row['step'] for row in rows][-1] == 240
    for key in ('loss/dynamics', 'loss/reward', 'loss/critic'):
        assert _mean(rows[-3:], key) < _mean(rows[:3], key), key
    out = trained.out
    for name in ('checkpoint.pt', 'final.pt', 'metrics.csv', 'losses.png', 'config.yaml',
                 'eval.csv', 'eval_returns.png'):
        assert (out / name).is_file(), name
    csv_rows = read_csv(out / 'metrics.csv')
    assert len(csv_rows) == len(rows) and 'loss/context' in csv_rows[-1]
    evals = read_csv(out / 'eval.csv')
    assert len(evals) == 2 and all(row['step'] == 240 for row in evals)
    assert len({row['context/torso_length'] for row in evals}) == 2


@pytest.mark.slow
def test_checkpoint_carries_data_normalisation_and_task_bounds(trained: Any) -> None:
    """The checkpoint rebuilds the agent with the bag's obs statistics and the task's bounds."""
    from sim_bridge.registry import make_task

    loaded = load_checkpoint(trained.out / 'final.pt', expect_task=TASK)
    task = make_task(TASK)
    try:
        low, high = task.action_bounds
        assert loaded.spec.action_low == tuple(map(float, low))
        assert loaded.spec.action_high == tuple(map(float, high))
        assert loaded.spec.obs_shape == (task.state_dim,)
    finally:
        task.close()
    assert loaded.step == 240 and loaded.spec.obs_std is not None
    assert loaded.spec.context_names == ('torso_length',)


@pytest.mark.slow
def test_resume_continues_step_count_and_optimizer(trained: Any, bags: Path,
                                                  tiny_config: Path, tmp_path: Path) -> None:
    """--resume goes on from the checkpoint's step with its optimizer state."""
    from zeus_ros.cli.train import main

    run = tmp_path / 'run'
    shutil.copytree(trained.out, run)
    before = load_checkpoint(run / 'checkpoint.pt').agent.optimizers['critic'].state_dict()
    code = main(['--bags', str(bags), '--config', str(tiny_config), '--out', str(run),
                 '--resume', '--updates', '280', '--no-eval', '--no-progress'])
    assert code == 0
    after = load_checkpoint(run / 'checkpoint.pt')
    assert after.step == 280
    steps = [row['step'] for row in read_csv(run / 'metrics.csv')]
    assert steps == sorted(steps) and steps[-1] == 280 and 240 in steps
    adam_steps = [float(s['step']) for s in before['state'].values()]
    resumed = [float(s['step']) for s in
               after.agent.optimizers['critic'].state_dict()['state'].values()]
    assert min(resumed) == min(adam_steps) + 40


@pytest.mark.slow
def test_resume_with_another_config_fails_clearly(trained: Any, bags: Path,
                                                  tmp_path: Path) -> None:
    """A resumed run whose network config differs names the differing field."""
    run = tmp_path / 'run'
    shutil.copytree(trained.out, run)
    other = load_config_from(CONFIG | {'k': 3, 'num_updates': 300})
    with pytest.raises(TrainError, match=r'k: checkpoint 5, now 3'):
        train([bags], other, run, resume=True, progress=False, log=lambda _m: None)
    with pytest.raises(TrainError, match='--resume'):
        train([bags], other, run, progress=False, log=lambda _m: None)


def test_a_method_without_the_context_loss_resumes_whatever_its_weight() -> None:
    """alpha_psi differs only where eq. 1's context loss applies (zeus), not for the others.

    `alpha_psi: auto` changed its value on two tasks (session 11): their no_context and oracle
    runs must continue, a zeus run must not.
    """
    from zeus_ros.offline.training.train import _config_differences

    for method, differs in (('zeus', True), ('zeus_no_context_loss', False),
                            ('no_context', False), ('oracle', False)):
        stored, wanted = (load_config_from(CONFIG | {'method': method, 'alpha_psi': alpha})
                          for alpha in (1.0, 0.0))
        found = _config_differences(stored, wanted, 240)
        assert found == (['alpha_psi: checkpoint 1.0, now 0.0'] if differs else []), method
        wider = load_config_from(CONFIG | {'method': method, 'alpha_psi': 0.0, 'k': 3})
        assert 'k: checkpoint 5, now 3' in _config_differences(stored, wider, 240)


@pytest.mark.slow
def test_resume_may_set_a_freeze_it_has_not_reached(trained: Any, bags: Path,
                                                     tmp_path: Path) -> None:
    """A resume at update 240 may set representation_frozen_from to 240 or later, not earlier.

    The field acts only from its update on, so the run so far is what that config would have done.
    """
    run = tmp_path / 'run'
    shutil.copytree(trained.out, run)
    early = load_config_from(CONFIG | {'num_updates': 260, 'representation_frozen_from': 100})
    with pytest.raises(TrainError, match=r'representation_frozen_from: checkpoint 0, now 100'):
        train([bags], early, run, resume=True, progress=False, log=lambda _m: None)
    later = load_config_from(CONFIG | {'num_updates': 260, 'representation_frozen_from': 240})
    train([bags], later, run, resume=True, progress=False, evaluate=False, log=lambda _m: None)
    before, after = (load_checkpoint(path).agent for path in
                     (trained.out / 'checkpoint.pt', run / 'checkpoint.pt'))
    assert after.config.representation_frozen_from == 240
    for name in ('encoder', 'psi'):
        assert all(torch.equal(a, b) for a, b in zip(
            after.modules[name].parameters(), before.modules[name].parameters(), strict=True))
    assert not all(torch.equal(a, b) for a, b in zip(
        after.modules['actor'].parameters(), before.modules['actor'].parameters(), strict=True))


def load_config_from(data: dict[str, Any]) -> Any:
    """A ZeusConfig from a dict (as a YAML file would give)."""
    from zeus_ros.learning.config import config_from_dict

    return config_from_dict(data)


@pytest.mark.slow
def test_eval_writes_tables_and_plots_with_a_valid_spearman(trained: Any, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture
                                                            ) -> None:
    """The eval command writes CSV/PNG, prints a table, reports Spearman rho in [-1, 1]."""
    from zeus_ros.cli.evaluate import main

    out = tmp_path / 'eval'
    code = main(['--checkpoint', str(trained.out / 'final.pt'), '--task', TASK,
                 '--split', 'interpolation', '--switch-every', str(EVERY), '--probe-steps', '0',
                 '--episodes', '1', '--out', str(out), '--no-progress'])
    assert code == 0
    for name in ('contexts.csv', 'summary.csv', 'switches.csv', 'returns.png',
                 'context_distances.png', 'switching.png'):
        assert (out / name).is_file(), name
    summary = {row['policy']: row for row in read_csv(out / 'summary.csv')}
    assert -1.0 <= summary['agent']['spearman'] <= 1.0
    # EPISODE steps switching every EVERY: 4 mid-episode switches, all in switches.csv (a row per
    # switch, as switching.png marks them); those to contexts where this tiny agent earns
    # nothing have no latency and say why. The printed summary counts the same rows.
    switches = read_csv(out / 'switches.csv')
    assert [row['step'] for row in switches] == [EVERY, 2 * EVERY, 3 * EVERY, 4 * EVERY]
    judged = [row for row in switches if row['judged'] == 'yes']
    assert all('latency' not in row and row['judged'].startswith('no: ') for row in switches
               if row not in judged)
    agent = summary['agent']
    assert (agent['switches'], agent['judged']) == (4, len(judged))
    assert agent['recovered'] == sum(row['recovered'] == 'True' for row in judged)
    printed = capsys.readouterr().out
    header, row = next((line.split(), next_line.split()) for line, next_line in
                       itertools.pairwise(printed.splitlines()) if 'judged' in line.split())
    shown = dict(zip(header, row, strict=True))
    assert (shown['switches'], shown['judged'], shown['recovered']) == (
        '4', str(len(judged)), str(agent['recovered']))
    assert 'random' in summary
    contexts = read_csv(out / 'contexts.csv')
    assert {row['policy'] for row in contexts} == {'agent', 'random', 'frozen_other',
                                                   'frozen_mean', 'frozen_train_mean',
                                                   'frozen_steady'}
    assert np.isfinite(agent['adaptation_value_train_mean'])
    steady = np.mean([r['return'] for r in contexts if r['policy'] == 'frozen_steady'])
    live = np.mean([r['return'] for r in contexts if r['policy'] == 'agent'])
    assert agent['adaptation_value_steady'] == pytest.approx(live - steady, abs=1e-3)
    assert 'spearman' in printed


@pytest.mark.slow
def test_eval_any_values_with_paired_frozen_context_diagnostics(trained: Any, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture
                                                                ) -> None:
    """--values: any torso lengths, several episodes each; live vs frozen on the same seeds."""
    from zeus_ros.cli.evaluate import main

    out = tmp_path / 'eval'
    code = main(['--checkpoint', str(trained.out / 'final.pt'), '--values', '0.65,1.4',
                 '--episodes', '2', '--probe-steps', '0', '--out', str(out), '--no-progress'])
    assert code == 0
    contexts = read_csv(out / 'contexts.csv')
    for policy in ('agent', 'frozen_other', 'frozen_mean', 'frozen_train_mean',
                   'frozen_steady', 'random'):
        mine = [row for row in contexts if row['policy'] == policy]
        assert sorted((row['context/torso_length'], row['episode']) for row in mine) == [
            (0.65, 0), (0.65, 1), (1.4, 0), (1.4, 1)], policy
    summary = {row['policy']: row for row in read_csv(out / 'summary.csv')}['agent']
    assert summary['split'] == 'custom' and summary['episodes'] == 2
    assert summary['sensitivity'] >= 0.0 and summary['spread_noise'] > 0.0
    live = np.mean([r['return'] for r in contexts if r['policy'] == 'agent'])
    frozen = np.mean([r['return'] for r in contexts if r['policy'] == 'frozen_mean'])
    assert summary['adaptation_value_mean'] == pytest.approx(live - frozen, abs=1e-3)
    # off the train values: frozen at what psi reads on the train values (a deployed robot's
    # question), the same episodes as a direct evaluation frozen there; computed once per
    # checkpoint and protocol beside the evaluation folders
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import (
        TRAIN_MEAN_FILE,
        evaluate,
        evaluate_contexts,
        train_mean_context,
    )

    stored = json.loads((tmp_path / TRAIN_MEAN_FILE).read_text())
    assert (stored['key']['episodes'], stored['key']['seed']) == (2, 100)
    train_mean = np.asarray(stored['context'])
    agent = InferenceAgent.from_checkpoint(trained.out / 'final.pt')
    values = [{'torso_length': 0.65}, {'torso_length': 1.4}]
    direct = evaluate_contexts(agent, values, episodes=2, seed=100, progress=False,
                               frozen=[train_mean, train_mean])
    at_train_mean = [r['return'] for r in contexts if r['policy'] == 'frozen_train_mean']
    assert sorted(at_train_mean) == pytest.approx(sorted(r['return'] for r in direct),
                                                  abs=1e-4)  # the CSV's 6 digits
    assert summary['adaptation_value_train_mean'] == pytest.approx(
        live - np.mean(at_train_mean), abs=1e-3)
    # the train split's own episodes store the same context as a direct computation (so
    # held-out splits do not roll them out again); one episode per value keeps this short
    run = tmp_path / 'run'
    evaluate(trained.out / 'final.pt', split='train', episodes=1, seed=100, probe_steps=0,
             out=run / 'eval_train', progress=False)
    from_train_split = json.loads((run / TRAIN_MEAN_FILE).read_text())
    assert (from_train_split['key']['episodes'], from_train_split['key']['seed']) == (1, 100)
    assert from_train_split['key']['checkpoint_sha256'] == stored['key']['checkpoint_sha256']
    np.testing.assert_allclose(from_train_split['context'],
                               train_mean_context(agent, episodes=1, seed=100), atol=1e-6)
    printed = capsys.readouterr().out
    assert 'sensitivity' in printed and 'frozen_other' in printed
    assert main(['--checkpoint', str(trained.out / 'final.pt'), '--values', '0.6,abc',
                 '--out', str(out)]) == 2
    assert 'could not convert' in capsys.readouterr().err


@pytest.mark.slow
def test_probe_beats_predicting_the_mean() -> None:
    """On random-policy Cheetah data the probe's held-out MSE is below the mean predictor's."""
    from zeus_ros.offline.evaluation.evaluate import random_rollout, split_values
    from zeus_ros.offline.evaluation.probe import probe_context

    values = split_values(TASK, 'train')
    rollout = random_rollout(TASK, values, 3000, every=50, seed=1, progress=False)
    result = probe_context([rollout], updates=800, progress=False)
    assert result.num_test > 0 and result.mse < result.baseline_mse


@pytest.mark.slow
def test_loop_collects_trains_and_retrains(tiny_config: Path, tmp_path: Path) -> None:
    """Two rounds: random bag + fresh training, then an agent bag + resumed training."""
    from zeus_ros.offline.rollout import parse_schedule
    from zeus_ros.offline.training.loop import run_loop

    results = run_loop(TASK, load_config(tiny_config), tmp_path, rounds=2, random_steps=300,
                       steps=200, updates=30, noise=0.2,
                       schedule=parse_schedule('switch:values=train,every=100'), seed=0,
                       progress=False, evaluate=False)
    assert [r.step for r in results] == [30, 60] and results[1].start_step == 30
    assert sorted(p.name for p in (tmp_path / 'bags').iterdir()) == ['bag_000', 'bag_001']
    assert load_checkpoint(tmp_path / 'run' / 'checkpoint.pt').step == 60
    # Round 2 continues the schedule where round 1 stopped (step 300: its 4th and 5th train
    # values), instead of starting over at the first one.
    from sim_bridge.families import load_preset
    from zeus_ros.offline.data.ingest import ingest_bags

    values = [v['torso_length'] for v in load_preset(TASK, 'train')]
    second = ingest_bags(tmp_path / 'bags' / 'bag_001')
    seen = sorted({round(float(c), 4) for ep in second.episodes for c in ep.context[:, 0]})
    assert seen == sorted(round(v, 4) for v in values[3:5]), seen


@pytest.mark.slow
def test_export_card_and_no_resume_from_an_export(trained: Any, bags: Path, tiny_config: Path,
                                                  tmp_path: Path) -> None:
    """`zeus export` writes a small checkpoint + card; training refuses to resume from it."""
    from zeus_ros.cli.export import main as export_main

    target = tmp_path / 'ship' / 'zeus_s0.pt'
    assert export_main(['--checkpoint', str(trained.out / 'final.pt'), '--out',
                        str(target), '--commit', 'abc123']) == 0
    card = target.with_suffix('.md').read_text()
    recorded = load_checkpoint(trained.out / 'final.pt').extra['code_commit']
    for needle in ('Cheetah-Run-v0', '`zeus`', recorded or 'abc123', 'sha256', 'seed | 0',
                   'transitions from 1 bag(s)', 'Not evaluated yet'):
        assert needle in card, needle
    assert 'pytest' in card or 'command' in card  # the recorded command line of this process
    # the context read-out, calibrated on the train contexts, is in the export and on the card
    readout = load_checkpoint(target).extra['context_readout']
    assert readout['names'] == ['torso_length'] and 'train contexts' in readout['fitted_on']
    assert '| context read-out | torso_length RMSE' in card
    run = tmp_path / 'resume'
    run.mkdir()
    shutil.copy(target, run / 'checkpoint.pt')
    with pytest.raises(TrainError, match='deployment export'):
        train([bags], load_config(tiny_config), run, resume=True, progress=False,
              log=lambda _m: None)
    assert export_main(['--checkpoint', str(target), '--out', str(target)]) == 2


@pytest.mark.slow
def test_eval_of_several_checkpoints_writes_tables_over_seeds(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture
                                                             ) -> None:
    """Two seeds of a method -> per-run evals, a resumable batch, mean ± s.e. tables.

    A tiny Cheetah-Run-v1 checkpoint (40-step episodes): the batch evaluates each checkpoint
    in a process of its own, where this module's short Cheetah-Run-v0 episodes do not apply.
    """
    from zeus_ros.cli.evaluate import main
    from zeus_ros.learning.checkpoint import save_checkpoint
    from zeus_ros.offline.evaluation.report import per_method

    from live_fixtures import tiny_checkpoint

    first = load_checkpoint(tiny_checkpoint(tmp_path / 'tiny.pt', task_name='Cheetah-Run-v1'))
    ships = tmp_path / 'ship'
    paths = []
    for seed in (0, 1):
        first.agent.config = first.config.replace(seed=seed)
        paths.append(save_checkpoint(ships / f'zeus_s{seed}.pt', first.agent, step=240,
                                     extra=first.extra))
    out = tmp_path / 'tables'
    argv = ['--checkpoint', str(ships), '--split', 'interpolation', '--switch-every', '10',
            '--probe-steps', '0', '--episodes', '1', '--out', str(out), '--no-progress',
            '--jobs', '2']  # one process per checkpoint
    assert main(argv) == 0
    runs = out / 'cheetah_run_v1_240'
    for seed in (0, 1):
        assert 'interpolation' in read_state(runs / f'zeus_s{seed}').evaluated
    rows = per_method(runs)
    assert len(rows) == 1 and rows[0]['seeds'] == 2 and rows[0]['split'] == 'interpolation'
    assert rows[0]['mean_return_se'] == pytest.approx(0.0, abs=1e-6)  # same weights twice
    assert (runs / 'returns.png').is_file() and (runs / 'summary.csv').is_file()
    assert '| zeus | interpolation | 2 |' in (out / 'tables.md').read_text()
    capsys.readouterr()
    assert main(argv) == 0
    assert '0 evaluation(s) to run' in capsys.readouterr().out
    with pytest.raises(SystemExit) as missing:  # a missing file: refused while parsing
        main(['--checkpoint', str(paths[0]), str(paths[0].with_name('x.pt')),
              '--out', str(out)])
    assert missing.value.code == 2
    assert 'x.pt: no such file or folder' in capsys.readouterr().err


@pytest.mark.slow
def test_loop_resume_extends_a_finished_loop(tiny_config: Path, tmp_path: Path) -> None:
    """--resume adds rounds to a finished loop without recollecting or retraining old ones."""
    from zeus_ros.cli.loop import main as loop_main

    argv = ['--task', TASK, '--config', str(tiny_config), '--out', str(tmp_path),
            '--random-steps', '300', '--steps', '200', '--updates', '20', '--no-eval',
            '--no-progress']
    assert loop_main([*argv, '--rounds', '1']) == 0
    assert loop_main([*argv, '--rounds', '2']) == 2  # exists: needs --resume
    assert loop_main([*argv, '--rounds', '2', '--resume']) == 0
    assert sorted(p.name for p in (tmp_path / 'bags').iterdir()) == ['bag_000', 'bag_001']
    assert load_checkpoint(tmp_path / 'run' / 'checkpoint.pt').step == 40
    assert loop_main([*argv, '--rounds', '2', '--resume']) == 0  # nothing left to do
    assert len(list((tmp_path / 'bags').iterdir())) == 2


@pytest.mark.slow
def test_set_overrides_config_fields_like_the_file(bags: Path, tiny_config: Path,
                                                   tmp_path: Path) -> None:
    """`zeus train --set k=3 batch_size=32`: the run is trained with (and records) those values."""
    from zeus_ros.cli.train import main

    out = tmp_path / 'run'
    assert main(['--bags', str(bags), '--config', str(tiny_config), '--out', str(out),
                 '--set', 'k=3', 'batch_size=32', '--set', 'actor_lr=3e-4', '--updates', '2',
                 '--no-eval', '--no-progress']) == 0
    recorded = yaml.safe_load((out / 'config.yaml').read_text())
    assert (recorded['k'], recorded['batch_size'], recorded['actor_lr']) == (3, 32, 3e-4)
    assert recorded['num_updates'] == 2 and recorded['hidden_dim'] == CONFIG['hidden_dim']
    assert load_checkpoint(out / 'final.pt').config.k == 3


@pytest.mark.slow
def test_loop_resume_reads_its_stored_flags_and_time_continues(
        tiny_config: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """--resume needs only --out and --rounds (flags from OUT/loop.json); time_s adds up."""
    from zeus_ros.cli.loop import main as loop_main

    assert loop_main(['--task', TASK, '--config', str(tiny_config), '--out', str(tmp_path),
                      '--rounds', '1', '--random-steps', '300', '--steps', '200',
                      '--updates', '20', '--no-eval', '--no-progress',
                      '--set', 'eval_episodes=1', 'checkpoint_interval=40']) == 0
    assert 'final.pt' in capsys.readouterr().out.splitlines()[-1]
    monkeypatch.chdir(tmp_path.parent)  # another folder: the stored config path is absolute
    assert loop_main(['--out', str(tmp_path), '--rounds', '2', '--resume',
                      '--set', 'checkpoint_interval=50']) == 0  # a given --set wins per field
    stored = yaml.safe_load((tmp_path / 'run' / 'config.yaml').read_text())
    assert (stored['eval_episodes'], stored['checkpoint_interval']) == (1, 50)
    steps = [p.name for p in (tmp_path / 'bags').iterdir()]
    assert sorted(steps) == ['bag_000', 'bag_001']
    assert load_checkpoint(tmp_path / 'run' / 'checkpoint.pt').step == 40  # --updates 20 kept
    times = [row['time_s'] for row in read_csv(tmp_path / 'run' / 'metrics.csv')]
    assert times == sorted(times) and len(times) == 2
    assert loop_main(['--out', str(tmp_path), '--rounds', '2', '--resume', '--task',
                      'Walker-Walk-v0']) == 2
    assert 'runs Cheetah-Run-v0' in capsys.readouterr().err
    assert loop_main(['--out', str(tmp_path / 'fresh'), '--rounds', '1']) == 2
    assert '--task and --config required' in capsys.readouterr().err


def _trace(reward: list[float], context: list[float], segment: list[int]) -> Any:
    from zeus_ros.offline.rollout import Trace

    n = len(reward)
    first = np.zeros(n, bool)
    first[0] = True
    return Trace(reward=np.asarray(reward, float), first=first,
                 context=np.asarray(context, float)[:, None], segment=np.asarray(segment),
                 psi=None, history_length=np.full(n, 5), obs=np.zeros((n, 1)),
                 action=np.zeros((n, 1)))


def test_adaptation_latency_counts_steps_back_to_steady_and_skips_zero_reward() -> None:
    """Latency = steps until the 10-step mean is within 10% of steady; no latency for r = 0."""
    from zeus_ros.offline.evaluation.evaluate import adaptation_latencies

    # 30 steps at context 1 (reward 1), then context 2: 5 bad steps, then reward 2 for 45 steps.
    reward = [1.0] * 30 + [0.0] * 5 + [2.0] * 45
    context = [1.0] * 30 + [2.0] * 50
    segment = [0] * 30 + [1] * 50
    rows = adaptation_latencies(_trace(reward, context, segment), {(1.0,): 1.0, (2.0,): 2.0})
    assert len(rows) == 1 and rows[0]['recovered']
    # First 10-step window within 10% of 2 (inclusive): one bad step left in it, mean 1.8.
    assert rows[0]['latency'] == 13
    # A context where the policy's steady reward is 0 has nothing to recover to: skipped.
    assert adaptation_latencies(_trace(reward, context, segment), {(2.0,): 0.0}) == []


def _experiment(name: str) -> Any:
    """The module experiments/<name>.py (a script, not a package)."""
    import importlib.util

    path = Path(__file__).resolve().parents[1] / 'experiments' / f'{name}.py'
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_context_scale_measures_the_psi_the_policy_sees(trained: Any) -> None:
    """experiments/context_scale.py: per-value psi spread, within-episode noise and norm."""
    row = _experiment('context_scale').context_scale(trained.out / 'final.pt', 'interpolation')
    assert row['method'] == 'zeus' and row['split'] == 'interpolation'
    assert row['spread'] > 0 and row['noise'] >= 0 and row['norm'] > 0
    assert np.isfinite([row['spread'], row['noise'], row['norm']]).all()


@pytest.mark.slow
def test_collection_curves_keep_coinciding_methods_apart(bags: Path, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """experiments/collection_curves.py: only trained runs (state.json or old marker).

    Methods with the very same curve each keep their own marker and dash.
    """
    import sys

    from matplotlib.figure import Figure

    from zeus_ros.offline.runs import mark_trained

    folder = tmp_path / 'task'
    bag = next(bags.glob('bag_*'))
    for name, round_ in itertools.product(('zeus_s0', 'no_context_s0', 'oracle_s0',
                                           'unfinished_s0'), range(3)):
        shutil.copytree(bag, folder / name / 'bags' / f'bag_{round_:03d}')  # three rounds
    mark_trained(folder / 'zeus_s0', 12.0)
    for name in ('no_context_s0', 'oracle_s0'):
        (folder / name / '.done_train').write_text('12\n')  # runs of experiments/run_one.sh
    module = _experiment('collection_curves')
    figures: list[Figure] = []
    save = Figure.savefig
    monkeypatch.setattr(Figure, 'savefig',
                        lambda fig, *a, **k: (figures.append(fig), save(fig, *a, **k))[1])
    monkeypatch.setattr(sys, 'argv', ['collection_curves', str(folder), '--out',
                                      str(tmp_path / 'out')])
    module.main()
    rows = read_csv(tmp_path / 'out' / 'collection.csv')
    assert sorted({r['method'] for r in rows}) == ['no_context', 'oracle', 'zeus']
    assert len(rows) == 9 and len({r['reward_per_step'] for r in rows}) == 1
    lines = [line for line in figures[0].axes[0].get_lines() if line.get_linestyle() != 'None']
    assert len(lines) == 3  # the curves, not the error-bar caps
    assert len({(line.get_marker(), line.get_linestyle()) for line in lines}) == 3
    assert (tmp_path / 'out' / 'collection.png').stat().st_size > 10_000


@pytest.mark.slow
def test_blind_steps_freeze_the_context_only_at_each_episode_start(trained: Any) -> None:
    """blind_steps d: the frozen context in the first d steps of every episode, live after.

    live_steps d: live in the first d steps, frozen after (the steady value of adaptation).
    """
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts

    agent = InferenceAgent.from_checkpoint(trained.out / 'final.pt')
    values = [{'torso_length': 0.7}]
    frozen = [np.full(agent.context_dim, 0.25, np.float32)]
    traces: list[Any] = []
    evaluate_contexts(agent, values, episodes=2, seed=3, progress=False, traces=traces,
                      frozen=frozen, blind_steps=4)
    trace = traces[0]
    starts = np.flatnonzero(trace.first)
    assert len(starts) >= 2
    for start in starts[:2]:
        assert np.allclose(trace.psi[start:start + 4], 0.25)
        assert not np.allclose(trace.psi[start + 4:start + 8], 0.25)
    always = evaluate_contexts(agent, values, episodes=1, seed=3, progress=False, frozen=frozen)
    blind_all = evaluate_contexts(agent, values, episodes=1, seed=3, progress=False,
                                  frozen=frozen, blind_steps=10_000)
    assert [r['return'] for r in always] == [r['return'] for r in blind_all]
    with pytest.raises(ValueError, match='needs a frozen_context'):
        evaluate_contexts(agent, values, episodes=1, seed=3, progress=False, blind_steps=2)
    # live_steps d: the other way round, live in the first d steps, frozen after
    traces.clear()
    evaluate_contexts(agent, values, episodes=2, seed=3, progress=False, traces=traces,
                      frozen=frozen, live_steps=4)
    trace = traces[0]
    for start in np.flatnonzero(trace.first)[:2]:
        assert not np.allclose(trace.psi[start + 1:start + 4], 0.25)
        assert np.allclose(trace.psi[start + 4:start + 8], 0.25)
    with pytest.raises(ValueError, match='give one'):
        evaluate_contexts(agent, values, episodes=1, seed=3, progress=False, frozen=frozen,
                          blind_steps=2, live_steps=2)


@pytest.mark.slow
def test_context_transform_maps_the_live_context_before_the_policy_acts(trained: Any) -> None:
    """A transform sees every live psi; the identity changes nothing, a constant is a freeze."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts

    agent = InferenceAgent.from_checkpoint(trained.out / 'final.pt')
    values = [{'torso_length': 0.7}]
    seen: list[np.ndarray] = []

    def identity(psi: np.ndarray) -> np.ndarray:
        seen.append(psi.copy())
        return psi

    live = evaluate_contexts(agent, values, episodes=1, seed=3, progress=False)
    same = evaluate_contexts(agent, values, episodes=1, seed=3, progress=False,
                             context_transform=identity)
    assert [r['return'] for r in same] == [r['return'] for r in live] and len(seen) > 10
    constant = np.full(agent.context_dim, 0.25, np.float32)
    frozen = evaluate_contexts(agent, values, episodes=1, seed=3, progress=False,
                               frozen=[constant])
    mapped = evaluate_contexts(agent, values, episodes=1, seed=3, progress=False,
                               context_transform=lambda psi: constant)
    assert [r['return'] for r in mapped] == [r['return'] for r in frozen]


@pytest.mark.slow
def test_context_lag_acts_on_the_estimate_of_l_steps_before_within_the_episode(
        trained: Any) -> None:
    """context_lag L: step k acts on the live estimate of step max(k - L, episode start)."""
    from zeus_ros.learning.inference import MAX_CONTEXT_LAG, InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts

    agent = InferenceAgent.from_checkpoint(trained.out / 'final.pt')
    values = [{'torso_length': 0.7}]
    for lag in (0, 2):
        seen: list[np.ndarray] = []  # every live estimate, in order

        def record(psi: np.ndarray, seen: list[np.ndarray] = seen) -> np.ndarray:
            seen.append(psi.copy())
            return psi

        traces: list[Any] = []
        evaluate_contexts(agent, values, episodes=2, seed=3, progress=False, traces=traces,
                          context_transform=record, context_lag=lag)
        trace = traces[0]
        starts = np.flatnonzero(trace.first)
        assert len(starts) >= 2 and len(seen) == len(trace.psi)
        start_of = np.maximum.accumulate(np.where(trace.first, np.arange(len(seen)), 0))
        for k in range(len(seen)):
            np.testing.assert_array_equal(trace.psi[k], seen[max(k - lag, start_of[k])])
        if lag:  # the estimates moved within the episode, so the lag showed
            assert not np.allclose(trace.psi[starts[0] + 5], seen[starts[0] + 5])
    for refused in (-1, MAX_CONTEXT_LAG + 1):  # the policy node's range, no wider
        with pytest.raises(ValueError, match=f'context_lag={refused}: must be between 0 and'):
            evaluate_contexts(agent, values, episodes=1, seed=3, progress=False,
                              context_lag=refused)


@pytest.mark.slow
def test_readme_order_train_eval_export_report_finds_the_evaluations(
        trained: Any, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Train -> eval -> export / report, each with its defaults: they meet.

    The card and the report see the evaluations `zeus eval` wrote (by default beside the
    checkpoint, or in any --out below the run folder); a checkpoint retrained since is 'Not
    evaluated yet' again.
    """
    from zeus_ros.cli import main as zeus
    from zeus_ros.learning.checkpoint import save_checkpoint

    run = tmp_path / 'runs' / 'cheetah'
    run.mkdir(parents=True)
    shutil.copy(trained.out / 'final.pt', run / 'final.pt')
    protocol = ['--episodes', '1', '--probe-steps', '0', '--switch-every', str(EVERY),
                '--no-progress']
    assert zeus(['eval', '--checkpoint', str(run / 'final.pt'), '--task', TASK,
                 '--split', 'interpolation', *protocol]) == 0
    assert zeus(['eval', '--checkpoint', str(run / 'final.pt'), '--split', 'train',
                 '--out', str(run / 'eval'), *protocol]) == 0  # the README's --out
    record = json.loads((run / 'eval_interpolation' / 'eval.json').read_text())
    assert (record['split'], record['method'], record['seed']) == ('interpolation', 'zeus', 0)
    capsys.readouterr()

    card_path = tmp_path / 'ship' / 'cheetah.pt'
    assert zeus(['export', '--checkpoint', str(run / 'final.pt'), '--out', str(card_path),
                 '--readout-steps', '0']) == 0
    assert 'the card shows the evaluations of train' in capsys.readouterr().out
    card = card_path.with_suffix('.md').read_text()
    assert 'Not evaluated yet' not in card
    for split, folder in (('train', 'eval'), ('interpolation', 'eval_interpolation')):
        agent = next(r for r in read_csv(run / folder / 'summary.csv') if r['policy'] == 'agent')
        assert f'| {split} | {agent["mean_return"]:.1f} |' in card, card

    assert zeus(['report', str(run)]) == 0
    table = (run / 'report' / 'table.md').read_text()
    assert '| zeus | train | 1 |' in table and '| zeus | interpolation | 1 |' in table, table
    runs = read_csv(run / 'report' / 'runs.csv')
    assert sorted(r['split'] for r in runs) == ['interpolation', 'train']
    assert all(r['eval_seconds'] > 0 for r in runs)

    loaded = load_checkpoint(run / 'final.pt')  # retrained: other weights, same path
    save_checkpoint(run / 'final.pt', loaded.agent, step=loaded.step + 1, extra=loaded.extra)
    capsys.readouterr()
    assert zeus(['export', '--checkpoint', str(run / 'final.pt'), '--out', str(card_path),
                 '--readout-steps', '0']) == 0
    assert f'no evaluation of {run / "final.pt"} found' in capsys.readouterr().out
    assert 'Not evaluated yet' in card_path.with_suffix('.md').read_text()


@pytest.mark.slow
def test_losses_png_of_a_short_run_has_no_empty_panels(trained: Any, bags: Path,
                                                       tiny_config: Path,
                                                       tmp_path: Path) -> None:
    """losses.png shows a panel only for a loss with a curve.

    A run shorter than log_interval logs each loss once: one compact text panel, not 13
    empty-looking ones; a longer run gets a panel with a curve per loss, nothing else.
    """
    from PIL import Image

    from zeus_ros.offline.evaluation.metrics import metric_series

    config = load_config(tiny_config).replace(num_updates=30, log_interval=1000)
    short = train([bags], config, tmp_path / 'short', evaluate=False, progress=False,
                  log=lambda _m: None)
    rows = read_csv(short.out / 'metrics.csv')
    keys = [k for k in rows[0] if k.startswith(('loss/', 'train/')) or k == 'updates_per_s']
    curves, single, empty = metric_series(rows, keys)
    assert len(rows) == 1 and not curves and len(single) + len(empty) == len(keys) > 10
    width, height = Image.open(short.out / 'losses.png').size
    assert width <= 700 and height <= 400, (width, height)  # one text panel (was 1386x1540)

    rows = read_csv(trained.out / 'metrics.csv')  # 12 logged rows
    curves, single, empty = metric_series(rows, keys)
    assert {key for key, _xs, ys in curves} == set(keys) and not single and not empty
    assert all(len(ys) == len(rows) for _key, _xs, ys in curves)
