"""Fault matrix, data rows: non-finite and wrong-length values from bag to checkpoint to load.

Real bags (collected on the task, then rewritten with the project's bag writer with NaN, Inf,
1e30 and short vectors injected), real training on a tiny config, real checkpoint files.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
import subprocess
import sys
from typing import Any
import warnings

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
import torch

from zeus_ros.bags.errors import IngestError
from zeus_ros.bags.schema import TOPIC_ACTION, TOPIC_STATE, TOPIC_STEP, codec
from zeus_ros.bags.writer import StepBagWriter
from zeus_ros.cli import collect, export
from zeus_ros.cli import train as train_command
from zeus_ros.learning.checkpoint import load_checkpoint, nonfinite_tensors, save_checkpoint
from zeus_ros.learning.errors import CheckpointError
from zeus_ros.offline.data.ingest import IngestWarning, ingest_bags
from zeus_ros.offline.training import train

from ros_harness import REPO, fresh_domain_id, ros_environment
from tiny_config import MINIMAL, config_fixture, write_config

TASK = 'Cheetah-Run-v0'

torch.set_num_threads(1)

Poison = Callable[[str, int, Any], None]


@pytest.fixture(scope='module')
def clean_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """400 random-policy steps of the real task, as `zeus collect` writes them."""
    out = tmp_path_factory.mktemp('clean')
    assert collect.main(['--task', TASK, '--steps', '400', '--out', str(out),
                         '--no-progress']) == 0
    return out / 'bag_000'


def _rewrite(src: Path, dst: Path, poison: Poison) -> Path:
    """Copy a bag message by message through StepBagWriter, letting `poison` edit each one."""
    cdc = codec()
    reader = Reader(src)
    reader.open()
    try:
        with StepBagWriter(dst, pixels=False) as writer:
            for conn, log_ns, raw in reader.messages():
                msg = cdc.deserialize(raw, conn.msgtype)
                if hasattr(msg, 'step'):
                    for name in ('data', 'applied_action', 'values'):
                        if isinstance(getattr(msg, name, None), np.ndarray):
                            setattr(msg, name, getattr(msg, name).copy())
                    poison(conn.topic, int(msg.step), msg)
                writer.write_serialized(conn.topic, log_ns, cdc.serialize(msg))
    finally:
        reader.close()
    return dst


def _issue_poison(topic: str, step: int, msg: Any) -> None:
    """The issue's rows: NaN state, NaN reward, NaN/1e30 applied actions, short states, Inf."""
    if topic == TOPIC_STATE and step % 7 == 3:
        msg.data[2] = np.nan
    if topic == TOPIC_STATE and step in (50, 51, 200):
        msg.data = msg.data[:-2].copy()
    if topic == TOPIC_STEP and step == 100 and not msg.first:
        msg.reward = float('nan')
    if topic == TOPIC_STEP and step % 13 == 5 and not msg.first:
        msg.applied_action[0] = np.nan if step % 26 == 5 else np.float32(1e30)
    if topic == TOPIC_ACTION and step == 30:
        msg.data[0] = np.inf


@pytest.fixture(scope='module')
def poisoned_bag(clean_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The clean bag with the issue's non-finite, huge and short values injected."""
    return _rewrite(clean_bag, tmp_path_factory.mktemp('poisoned') / 'bag_000', _issue_poison)


tiny_config = config_fixture(MINIMAL)


def test_ingest_drops_bad_values_and_reports_each_topic_and_field(poisoned_bag: Path,
                                                                 clean_bag: Path) -> None:
    """Every bad field is reported once with its count and first steps; no value survives."""
    clean = ingest_bags(clean_bag)
    with pytest.warns(IngestWarning) as caught:
        data = ingest_bags(poisoned_bag)
    text = '\n'.join(str(w.message) for w in caught)
    issues = {(i.topic, i.kind, i.detail.split(':')[0]): i for i in data.report.issues}
    state_nan = issues[(TOPIC_STATE, 'nonfinite', 'data')]
    assert state_nan.step == 3 and 'at steps 3, 10, 17, 24, 31, ...' in state_nan.detail
    short = issues[(TOPIC_STATE, 'length', 'data')]
    assert short.step == 50 and '3 message(s)' in short.detail and 'steps 50, 51, 200' in text
    assert issues[(TOPIC_STEP, 'nonfinite', 'reward')].step == 100
    act = issues[(TOPIC_STEP, 'nonfinite', 'applied_action')]
    assert act.step == 5 and 'steps 5, 18, 31' in act.detail
    assert (TOPIC_ACTION, 'nonfinite', 'data') in issues
    assert data.report.dropped > 0
    assert data.num_transitions == clean.num_transitions - data.report.dropped
    assert 'dropped for bad values' in data.report.summary()
    for ep in data.episodes:
        assert np.isfinite(ep.obs).all() and np.isfinite(ep.reward).all()
        assert np.isfinite(ep.action).all() and np.abs(ep.action).max() <= 1.0
        assert not np.isinf(ep.policy_action).any()
        assert not set(ep.steps[1:].tolist()) & ({100} | set(range(5, 400, 13)))


def test_strict_refuses_the_poisoned_bag(poisoned_bag: Path) -> None:
    """--strict: the same findings refuse the bag instead of dropping data."""
    with pytest.raises(IngestError, match=r'(?s)--strict: the bag is refused.*nonfinite: data'), \
            warnings.catch_warnings():
        warnings.simplefilter('ignore', IngestWarning)
        ingest_bags(poisoned_bag, strict=True)


def test_bags_of_another_state_length_are_refused_by_name(clean_bag: Path,
                                                          tmp_path: Path) -> None:
    """A second bag whose every state is shorter is named; no numpy shape traceback."""
    def shorten(topic: str, _step: int, msg: Any) -> None:
        if topic == TOPIC_STATE:
            msg.data = msg.data[:-1].copy()

    short = _rewrite(clean_bag, tmp_path / 'short', shorten)
    with pytest.raises(IngestError, match=r'short: /zeus/observation/state data has 16 values, '
                       'earlier bags 17'):
        ingest_bags([clean_bag, short])


@pytest.mark.slow
def test_train_on_the_poisoned_bag_writes_finite_checkpoints(poisoned_bag: Path,
                                                             tiny_config: Path, tmp_path: Path,
                                                             capsys: Any) -> None:
    """`zeus train` drops the bad transitions (saying so) and every tensor it saves is finite."""
    code = train_command.main(['--bags', str(poisoned_bag), '--config', str(tiny_config), '--out',
                       str(tmp_path / 'run'), '--no-eval', '--no-progress'])
    assert code == 0, capsys.readouterr().err
    for name in ('checkpoint.pt', 'final.pt'):
        state = torch.load(tmp_path / 'run' / name, weights_only=True)['state']
        assert nonfinite_tensors(state)[0] == []
    assert 'zeus train: warning: ' in capsys.readouterr().err
    code = train_command.main(['--bags', str(poisoned_bag), '--config', str(tiny_config), '--out',
                       str(tmp_path / 'strict'), '--no-eval', '--no-progress', '--strict'])
    err = capsys.readouterr().err
    assert code == 2 and '--strict: the bag is refused' in err and 'Traceback' not in err
    assert not (tmp_path / 'strict').exists()


@pytest.mark.slow
def test_a_nan_gradient_stops_training_naming_the_update_and_last_good_checkpoint(
        clean_bag: Path, tiny_config: Path, tmp_path: Path, capsys: Any,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """NaN critic gradients from update 5 on: exit 1 at update 5, naming checkpoint.pt @ 4.

    That checkpoint stays finite and loadable; no final.pt is written.
    """
    from zeus_ros.learning import agent as agent_module

    make_agent = agent_module.make_agent
    poison = {'on': False}

    def poisoned_agent(*args: Any, **kwargs: Any) -> Any:
        agent = make_agent(*args, **kwargs)
        update = agent.update
        for param in agent.modules['critic'].parameters():
            param.register_hook(lambda g: g * float('nan') if poison['on'] else g)

        def guarded(batch: Any, pair: Any, step: int) -> dict[str, float]:
            poison['on'] = step >= 4  # the fifth update (0-based step 4)
            return update(batch, pair, step)

        agent.update = guarded
        return agent

    monkeypatch.setattr(agent_module, 'make_agent', poisoned_agent)
    out = tmp_path / 'run'
    code = train_command.main(['--bags', str(clean_bag), '--config', str(tiny_config), '--out',
                       str(out), '--no-eval', '--no-progress'])
    err = capsys.readouterr().err
    assert code == 1, err
    assert err.count('\n') == 1 and 'Traceback' not in err
    assert 'zeus train: update 5: ' in err and 'non-finite parameters in' in err
    assert 'critic' in err.split('non-finite parameters in')[1].split('(')[0]
    assert f'the last good checkpoint is {out / "checkpoint.pt"} (update 4)' in err
    assert load_checkpoint(out / 'checkpoint.pt').step == 4
    assert not (out / 'final.pt').exists()


@pytest.mark.slow
def test_a_diverging_learning_rate_stops_at_update_one(clean_bag: Path, tiny_config: Path,
                                                       tmp_path: Path) -> None:
    """A real divergence (critic_lr 1e30) through the CLI: one line, exit 1, no checkpoint."""
    config = tmp_path / 'boom.yaml'
    write_config(config, MINIMAL | {'critic_lr': 1e30})
    result = subprocess.run(
        [sys.executable, '-m', 'zeus_ros.cli', 'train', '--bags', str(clean_bag), '--config',
         str(config), '--out', str(tmp_path / 'run'), '--no-eval', '--no-progress',
         '--threads', '1'], cwd=REPO, capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 1, result.stderr
    assert 'zeus train: update 1: ' in result.stderr and 'nan' in result.stderr
    assert 'no checkpoint was saved before it' in result.stderr
    assert 'Traceback' not in result.stderr
    assert not (tmp_path / 'run' / 'checkpoint.pt').exists()


@pytest.fixture(scope='module')
def nan_checkpoint(clean_bag: Path, tiny_config: Path,
                   tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(a good checkpoint, the same with the observation normaliser's first weight NaN)."""
    from zeus_ros.learning.config import load_config

    out = tmp_path_factory.mktemp('good')
    result = train.train([clean_bag], load_config(tiny_config), out, evaluate=False,
                         progress=False, log=lambda _m: None)
    payload = torch.load(result.checkpoint, weights_only=True)
    tensor = next(t for t in payload['state']['modules']['actor'].values()
                  if t.is_floating_point())
    tensor.view(-1)[0] = float('nan')
    bad = out / 'nan.pt'
    torch.save(payload, bad)
    return result.checkpoint, bad


@pytest.mark.slow
def test_every_offline_load_refuses_a_nan_checkpoint_in_one_line(
        nan_checkpoint: tuple[Path, Path], tmp_path: Path, capsys: Any) -> None:
    """load_checkpoint, zeus export, zeus eval and zeus collect: one line naming the tensor."""
    good, bad = nan_checkpoint
    load_checkpoint(good)
    with pytest.raises(CheckpointError, match=r'refused: 1 of \d+ tensors hold NaN/Inf '
                       r'\(first: modules\.actor\.'):
        load_checkpoint(bad)
    from zeus_ros.cli import evaluate

    for main, argv in (
            (export.main, ['--checkpoint', str(bad), '--out', str(tmp_path / 'x.pt')]),
            (evaluate.main, ['--checkpoint', str(bad), '--out', str(tmp_path / 'eval'),
                             '--no-progress']),
            (collect.main, ['--task', TASK, '--checkpoint', str(bad), '--out',
                            str(tmp_path / 'bags'), '--steps', '5', '--no-progress'])):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and 'NaN/Inf' in err and str(bad) in err, err
    assert not (tmp_path / 'x.pt').exists() and not (tmp_path / 'bags').exists()


@pytest.mark.slow
def test_saving_nan_weights_is_refused_and_writes_nothing(nan_checkpoint: tuple[Path, Path],
                                                          tmp_path: Path) -> None:
    """save_checkpoint never writes a non-finite state (no file, no temp file)."""
    loaded = load_checkpoint(nan_checkpoint[0])
    with torch.no_grad():
        next(loaded.agent.modules['critic'].parameters()).view(-1)[0] = float('inf')
    with pytest.raises(CheckpointError, match='not saved: 1 of'):
        save_checkpoint(tmp_path / 'c.pt', loaded.agent, step=1)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.ros
def test_nodes_refuse_a_nan_checkpoint(nan_checkpoint: tuple[Path, Path],
                                       tmp_path: Path) -> None:
    """The policy and context_estimator under zeus launch exit 2 naming the file and the NaN."""
    bad = nan_checkpoint[1]
    params = tmp_path / 'params.yaml'
    params.write_text(f'/**:\n  ros__parameters:\n    task: {TASK}\n'
                      f'/**/policy:\n  ros__parameters:\n    checkpoint: {bad}\n'
                      f'/**/context_estimator:\n  ros__parameters:\n    checkpoint: {bad}\n')
    for node in ('policy', 'context_estimator'):
        result = subprocess.run(
            [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params', str(params),
             '--nodes', node, '--timeout', '60'], cwd=REPO,
            env=ros_environment(fresh_domain_id()), capture_output=True, text=True,
            timeout=120, check=False)
        assert result.returncode == 1, result.stdout + result.stderr
        assert f"node '{node}' died with exit code 2" in result.stderr
        lines = [line for line in result.stdout.splitlines() if 'NaN/Inf' in line]
        assert lines and str(bad) in lines[0] and 'Traceback' not in result.stdout
