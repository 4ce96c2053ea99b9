"""Continual deployment, the library (zeus_ros/offline/training/continual.py), on real data.

Closed splits only; a bounded replay mix; a candidate continued from a deployment export
(fresh critics warmed up) and from a full checkpoint; the paired gate refuses a candidate
trained on corrupted rewards and deploys a genuinely better one; every decision is a history
line. Tiny budgets: the whole file takes about a minute on two shared cores.
"""

from __future__ import annotations

import json
from pathlib import Path
import shutil

from continual_fixtures import WEAK_TASK, record, weak_checkpoint
import pytest
import torch

from zeus_ros.bags.recording import closed_splits, split_steps
from zeus_ros.offline.training import continual as c
from zeus_ros.system.continual_settings import ContinualSettings, read_history
from zeus_ros.system.launch_defaults import zoo_checkpoint

BIAS = 'Cheetah-Bias-v0'


@pytest.fixture(autouse=True)
def one_thread() -> None:
    torch.set_num_threads(1)  # as the live trainer runs


@pytest.fixture(scope='module')
def bias_recording(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp('rec') / 'run1'
    return record(folder, BIAS, [-0.5, 0.5, -0.45, 0.45], zoo_checkpoint(BIAS), splits=3,
                  steps=240, every=40)


@pytest.mark.slow
def test_closed_splits_skip_the_bag_being_written(bias_recording: list[Path],
                                                  tmp_path: Path) -> None:
    folder = tmp_path / 'run1'
    for bag in bias_recording:
        shutil.copytree(bag, folder / bag.name)
    writing = folder / 'run1_003'  # the recorder's open split: provisional metadata
    shutil.copytree(bias_recording[0], writing)
    meta = writing / 'metadata.yaml'
    meta.write_text(meta.read_text().replace('custom_data: null',
                                             'custom_data: {zeus_bag_state: provisional}'))
    unfinished = folder / 'run1_004'  # killed before its first metadata
    unfinished.mkdir()
    shutil.copy(next(bias_recording[0].glob('*.mcap')), unfinished / 'run1_004.mcap')
    splits = closed_splits(folder)
    assert [b.name for b in splits] == ['run1_000', 'run1_001', 'run1_002']
    assert [split_steps(b) for b in splits] == [240, 240, 240]
    assert closed_splits(tmp_path / 'nothing_yet') == []


@pytest.mark.slow
def test_replay_mix_is_bounded(bias_recording: list[Path]) -> None:
    new = bias_recording[2:]
    (old,) = c.replay_mix(bias_recording, new, ContinualSettings())  # 240 old for 240 new
    assert old in bias_recording[:2]
    half = ContinualSettings(old_ratio=0.5)  # 120 old steps allowed: no whole split fits
    assert c.replay_mix(bias_recording, new, half) == []
    capped = ContinualSettings(old_ratio=10, max_old_steps=300)
    assert len(c.replay_mix(bias_recording, bias_recording[2:], capped)) == 1


@pytest.mark.slow
def test_without_context_truth_the_read_out_names_the_seen_contexts(
        bias_recording: list[Path], tmp_path: Path) -> None:
    """A robot records no truth: the deployed checkpoint's read-out of each segment stands in."""
    from dataclasses import replace

    from zeus_ros.offline.data.ingest import ingest_bags
    from zeus_ros.offline.training.continual_seen import seen_contexts

    dataset = ingest_bags(bias_recording)
    assert seen_contexts(zoo_checkpoint(BIAS), dataset, 6).source == 'truth'
    blind = replace(dataset, context_names=(), episodes=[
        replace(ep, context=ep.context[:, :0]) for ep in dataset.episodes])
    seen = seen_contexts(zoo_checkpoint(BIAS), blind, 6)
    assert seen.source == 'read-out' and 'R^2' in seen.detail, seen
    biases = [value['motor_bias'] for value in seen.values]
    assert len(biases) == 6 and min(biases) < -0.2 and max(biases) > 0.2  # truth: +-0.45..0.5
    assert all(-1.0 <= b <= 1.0 for b in biases)  # inside the family's declared range
    weak = weak_checkpoint(tmp_path / 'weak.pt')  # no read-out stored: the train values
    none = seen_contexts(weak, blind, 6)
    assert none.source == 'none' and none.values == [] and '--readout-steps' in none.detail


@pytest.mark.slow
def test_gate_refuses_a_candidate_trained_on_corrupted_rewards(
        bias_recording: list[Path], tmp_path: Path) -> None:
    zoo = zoo_checkpoint(BIAS)
    settings = ContinualSettings(warmup_updates=50, updates=100, episodes=1,
                                 max_seen_values=4)
    history = tmp_path / 'history.jsonl'
    result = c.continual_round(zoo, bias_recording[1:], bias_recording, tmp_path / 'bad',
                               history, settings, corrupt_rewards=True)
    assert result.candidate.warmup_updates == 50  # an export: fresh critics warmed up first
    assert sorted(v['motor_bias'] for v in result.candidate.seen) == [-0.5, -0.45, 0.45, 0.5]
    assert not result.gate.deploy, result.gate.summary()
    assert result.gate.gain < 0
    assert {v['where'] for v in result.gate.values} == {'seen', 'train'}
    assert len(result.gate.values) == 4 + 8  # seen + every train value of the family
    (line,) = read_history(history)
    assert line['decision'] == 'refuse' and line['corrupt_rewards'] is True
    assert line['sha256'] == result.candidate.sha256 and line['reason']
    card = (tmp_path / 'bad' / 'card.json').read_text()
    assert '"corrupt_rewards": true' in card
    assert c.resume_from(result, settings, corrupt_rewards=True) is None  # never continued
    # a later round continuing a refused candidate: its critics, no warm-up; gated against
    # the deployed checkpoint all the same
    again = c.continual_round(zoo, bias_recording[1:], bias_recording, tmp_path / 'next',
                              history, settings, start=result.candidate.path)
    assert again.candidate.warmup_updates == 0
    line = read_history(history)[-1]
    assert line['started_from'] == str(result.candidate.path) and line['deployed'] == str(zoo)


def _round(deploy: bool, gain: float) -> c.RoundResult:
    gate = c.GateResult(deploy, '', gain, 1.0, 2.0, -50.0, -50.0 + gain)
    candidate = c.Candidate(Path('/runs/round_002/candidate.pt'), 'ab' * 32, [], [], 0, 0, 0,
                            0.0)
    return c.RoundResult(candidate, gate, {})


def test_only_a_refused_candidate_that_gained_is_continued() -> None:
    settings = ContinualSettings()
    assert c.resume_from(_round(False, 8.0), settings) == Path('/runs/round_002/candidate.pt')
    assert c.resume_from(_round(False, -3.0), settings) is None  # no progress: start afresh
    assert c.resume_from(_round(True, 30.0), settings) is None  # deployed: it is the start
    assert c.resume_from(_round(False, 8.0), settings, corrupt_rewards=True) is None
    off = ContinualSettings(resume_refused=False)
    assert c.resume_from(_round(False, 8.0), off) is None


@pytest.mark.slow
def test_gate_deploys_a_better_candidate_paired_on_the_same_seeds(tmp_path: Path) -> None:
    weak = weak_checkpoint(tmp_path / 'weak.pt')
    bags = record(tmp_path / 'run2', WEAK_TASK, [0.75, 1.25], weak, splits=2, steps=400)
    # bc_weight 0: a weak policy has nothing worth staying near
    settings = ContinualSettings(updates=500, episodes=1, max_seen_values=2,
                                 max_train_values=2, bc_weight=0.0, bc_weight_new=-1.0)
    same = c.gate(weak, weak, [{'torso_length': 1.25}], settings)
    assert same.gain == 0 and not same.deploy  # paired: same initial states, same returns
    history = tmp_path / 'history.jsonl'
    result = c.continual_round(weak, bags[1:], bags, tmp_path / 'good', history, settings)
    assert result.candidate.warmup_updates == 0  # a full checkpoint brings its critics
    assert result.candidate.old_bags == [str(bags[0])]
    assert result.gate.deploy, result.gate.summary()
    assert result.gate.gain >= max(settings.margin, 2 * result.gate.se)
    assert read_history(history)[-1]['decision'] == 'deploy'


@pytest.mark.slow
def test_a_rehearsed_round_keeps_the_deployed_actor_at_the_train_values(
        bias_recording: list[Path], tmp_path: Path) -> None:
    """With a rehearsal the candidate's actor is gated: the deployed one at train contexts.

    So the gate's forgetting budget at the train values measures next to nothing.
    """
    from zeus_ros.learning.checkpoint import load_checkpoint
    from zeus_ros.learning.gated_actor import GatedActor

    zoo = zoo_checkpoint(BIAS)
    settings = ContinualSettings(warmup_updates=50, updates=200, episodes=2,
                                 max_seen_values=2, rehearsal_steps=1600)
    rehearsal = c.rehearsal_bag(zoo, tmp_path / 'rehearsal', settings)
    assert rehearsal is not None and c.rehearsal_bag(zoo, tmp_path / 'rehearsal',
                                                     settings) == rehearsal  # made once
    lines: list[str] = []
    result = c.continual_round(zoo, bias_recording[1:], bias_recording, tmp_path / 'round',
                               tmp_path / 'history.jsonl', settings, rehearsal=rehearsal,
                               log=lines.append)
    assert any('actor gated on' in line for line in lines)
    loaded = load_checkpoint(result.candidate.path, load_optimizers=False)
    assert isinstance(loaded.agent.modules['actor'], GatedActor)
    assert loaded.config.actor_gate > 0
    train = [v for v in result.gate.values if v['where'] == 'train']
    assert len(train) == 8
    assert max(abs(v['diff']) for v in train) < 1.0, train
    progress = json.loads((tmp_path / 'round' / 'progress.json').read_text())
    assert progress['phase'] == 'gate' and progress['done'] == progress['total']


def test_live_check_pairs_segments_by_context_and_rolls_back_a_loss() -> None:
    from zeus_ros.system.continual_watch import LiveCheck, SegmentReturns

    returns = SegmentReturns()
    # before the swap (in segment 2): context 1.0 earns -1, context 2.0 earns -2 per step;
    # after it, context 2.0 earns -2.5, context 1.0 -1.5, then 3.0 (never met before)
    plan = [(1.0, -1.0), (2.0, -2.0), (1.0, -1.0), (2.0, -2.5), (3.0, -9.0), (1.0, -1.5),
            (2.0, 0.0)]
    for segment, (context, reward) in enumerate(plan):
        returns.on_truth(segment, [context])
        returns.on_step(0.0, first=True)  # a reset earns nothing
        for _ in range(10):
            returns.on_step(reward, first=False)
    check = LiveCheck(2, 0, gain=5.0, tolerance=0.1, tolerance_floor=2.0, episode_length=40)
    decision, change, allowed = check.verdict(returns)  # segments 3 and 5: paired; 4 skipped
    assert decision == 'rollback' and change == -20.0 and allowed == 6.0  # -0.5 per step
    lenient = LiveCheck(2, 0, gain=5.0, tolerance=0.5, tolerance_floor=2.0, episode_length=40)
    assert lenient.verdict(returns)[0] == 'keep'  # 50 % of |-60| allowed
    assert LiveCheck(2, 0, 0, 0.1, 2.0, 40, segments=3).verdict(returns) is None  # 6 running


@pytest.mark.slow
def test_retention_deletes_the_oldest_splits_but_never_the_protected(
        bias_recording: list[Path], tmp_path: Path) -> None:
    from zeus_ros.system.continual_watch import folder_bytes, prune_recording

    copies = []
    for bag in bias_recording:
        copies.append(tmp_path / bag.name)
        shutil.copytree(bag, copies[-1])
    total = sum(folder_bytes(b) for b in copies)
    keep = total - folder_bytes(copies[1])  # one split too many
    removed = prune_recording(copies, keep_bytes=keep, protect=copies[:1])
    assert removed == [copies[1]]  # the oldest that is not protected
    assert [b.exists() for b in copies] == [True, False, True]
    assert prune_recording(copies, keep_bytes=0) == []  # 0: keep everything


def test_novelty_alarm_needs_a_full_window_mostly_novel() -> None:
    from zeus_ros.system.continual_watch import NoveltyAlarm

    alarm = NoveltyAlarm(window=10, fraction=0.5)
    for _ in range(9):
        alarm.on_novelty(True)
    assert not alarm.raised  # 9 scored steps: the window is not full yet
    alarm.on_novelty(False)
    assert alarm.raised and alarm.novel_share == 0.9
    for _ in range(6):
        alarm.on_novelty(False)  # the last 10: 3 novel
    assert not alarm.raised and alarm.novel_share == 0.3
    off = NoveltyAlarm(window=0, fraction=0.5)
    off.on_novelty(True)
    assert not off.raised
    with pytest.raises(ValueError, match='fraction'):
        NoveltyAlarm(window=10, fraction=0.0)


@pytest.mark.slow
def test_zeus_continual_round_writes_its_answer(tmp_path: Path) -> None:
    """The node's child process: a request in, an answer out; a failed round says why."""
    import json
    import subprocess
    import sys

    request = {'deployed': str(tmp_path / 'gone.pt'), 'first_checkpoint': str(tmp_path / 'x'),
               'rehearsal': str(tmp_path / 'rehearsal'), 'new_bags': [], 'splits': [],
               'out': str(tmp_path / 'round_001'), 'history': str(tmp_path / 'history.jsonl'),
               'settings': {'rehearsal_steps': 0}, 'corrupt_rewards': False, 'forced': False,
               'resume_from': None, 'threads': 1, 'result': str(tmp_path / 'result.json')}
    path = tmp_path / 'request.json'
    path.write_text(json.dumps(request))
    command = [sys.executable, '-m', 'zeus_ros.cli', 'continual-round', '--request']
    done = subprocess.run([*command, str(path)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, done.stderr
    answer = json.loads((tmp_path / 'result.json').read_text())
    assert answer['status'] == 'failed' and answer['error'] == 'CheckpointError'
    assert 'gone.pt' in answer['reason'] and 'CheckpointError' in done.stderr  # the traceback
    assert read_history(tmp_path / 'history.jsonl') == []  # no gate line
    bad = subprocess.run([*command, str(tmp_path / 'none.json')], capture_output=True,
                         text=True, timeout=300)
    assert bad.returncode == 2 and 'cannot read the request' in bad.stderr


def test_a_restart_resumes_from_the_history(tmp_path: Path) -> None:
    """The last swap (unless rolled back), the refused chain and the counts come back."""
    from zeus_ros.system.continual_settings import append_history, resume_point

    first, second, chain = (tmp_path / f'{n}.pt' for n in ('first', 'second', 'chain'))
    for path in (first, second, chain):
        path.write_bytes(b'x')
    history = tmp_path / 'history.jsonl'
    assert resume_point(read_history(history)).rounds == 0  # nothing to resume
    for line in (
            {'event': 'start'}, {'event': 'round', 'round': 1},
            {'event': 'gate', 'round': 1, 'decision': 'deploy'},
            {'event': 'swap', 'round': 1, 'checkpoint': str(first)},
            {'event': 'live_check', 'decision': 'keep'},
            {'event': 'round', 'round': 2}, {'event': 'gate', 'decision': 'refuse'},
            {'event': 'chain', 'round': 2, 'resume_from': str(chain)},
            {'event': 'round', 'round': 3}, {'event': 'stopped', 'round': 3}):
        append_history(history, line)
    point = resume_point(read_history(history))
    assert (point.deployed, point.resume, point.rounds) == (first, chain, 3)
    assert point.counts == {'swaps': 1, 'refusals': 1, 'rollbacks': 0, 'failures': 0}
    append_history(history, {'event': 'swap', 'round': 4, 'checkpoint': str(second)})
    append_history(history, {'event': 'live_check', 'decision': 'rollback',
                             'rolled_back_to': str(first), 'error': None})
    point = resume_point(read_history(history))
    assert (point.deployed, point.resume, point.rounds) == (first, None, 4)
    first.unlink()  # a file gone from disk is not resumed from
    assert resume_point(read_history(history)).deployed is None
