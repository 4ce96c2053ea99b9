"""Fault matrix, resume rows: `zeus loop --resume` after kill -9 during collection."""

from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

from zeus_ros.offline.data.ingest import ingest_bags

from ros_harness import REPO
from tiny_config import MINIMAL, write_config

# kill -9 at each phase of a round: ~2.5 min, so `make faults` runs them, `make test` does not
# (issue 15: the fault matrix in make test where it takes a few minutes, the rest in make faults).
pytestmark = pytest.mark.faults_only

TASK = 'Cheetah-Run-v0'
CONFIG = MINIMAL | {'num_updates': 4}
STEPS = 12000


def _loop(out: Path, config: Path, *extra: str) -> list[str]:
    return [sys.executable, '-m', 'zeus_ros.cli', 'loop', '--task', TASK, '--config',
            str(config), '--out', str(out), '--rounds', '1', '--random-steps', str(STEPS),
            '--updates', '4', '--no-eval', '--no-progress', *extra]


def test_loop_resume_after_kill_during_collection_recovers_and_completes_the_round(
        tmp_path: Path) -> None:
    """Kill -9 mid-collection, then --resume: the unfinished bag is named and recovered.

    The missing steps go to bag_000_rest1 and training sees the full round; a rerun without
    --resume is refused.
    """
    config = write_config(tmp_path / 'tiny.yaml', CONFIG)
    out = tmp_path / 'loop'
    mcap = out / 'bags' / 'bag_000' / 'bag_000.mcap'
    with subprocess.Popen(_loop(out, config), cwd=REPO, stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL) as proc:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if mcap.is_file() and mcap.stat().st_size > 2_500_000:
                os.kill(proc.pid, signal.SIGKILL)
                break
            time.sleep(0.05)
        assert proc.wait(30) == -signal.SIGKILL, 'the collection ended before the kill'
    assert not (out / 'bags' / 'bag_000' / 'metadata.yaml').exists()

    again = subprocess.run(_loop(out, config), cwd=REPO, capture_output=True, text=True,
                           timeout=120, check=False)
    assert again.returncode == 2 and 'pass --resume' in again.stderr, again.stderr

    result = subprocess.run(_loop(out, config, '--resume'), cwd=REPO, capture_output=True,
                            text=True, timeout=300, check=False)
    text = result.stdout + result.stderr
    assert result.returncode == 0, text
    assert f'{out / "bags" / "bag_000"} is unfinished' in text and 'recovered' in text
    held = int(text.split('bag_000 hold(s) ')[1].split(' ')[0])
    assert 0 < held < STEPS
    assert f'of the {STEPS} steps requested' in text
    assert f'collecting the missing {STEPS - held}' in text
    assert (out / 'bags' / 'bag_000_rest1' / 'metadata.yaml').is_file()
    data = ingest_bags(out / 'bags')
    assert data.report.steps == STEPS
    assert 'train: ' in text and 'from 2 bag(s)' in text and (out / 'run' / 'final.pt').is_file()
    assert 'cut short' not in text, 'the completed round is not short'


def test_loop_resume_after_kill_during_training_continues_from_the_last_checkpoint(
        tmp_path: Path) -> None:
    """Kill -9 once checkpoint.pt exists; --resume trains from its update to the round's total."""
    from zeus_ros.learning.checkpoint import load_checkpoint

    config = write_config(tmp_path / 'tiny.yaml', CONFIG | {'checkpoint_interval': 5})
    out = tmp_path / 'loop'
    argv = [sys.executable, '-m', 'zeus_ros.cli', 'loop', '--task', TASK, '--config',
            str(config), '--out', str(out), '--rounds', '1', '--random-steps', '400',
            '--updates', '40', '--no-eval', '--no-progress']
    checkpoint = out / 'run' / 'checkpoint.pt'
    with subprocess.Popen(argv, cwd=REPO, stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL) as proc:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if checkpoint.is_file():
                os.kill(proc.pid, signal.SIGKILL)
                break
            time.sleep(0.02)
        assert proc.wait(30) == -signal.SIGKILL, 'training ended before the kill'
    saved = load_checkpoint(checkpoint).step
    assert 0 < saved < 40 and not (out / 'run' / 'final.pt').exists()
    result = subprocess.run([*argv, '--resume'], cwd=REPO, capture_output=True, text=True,
                            timeout=300, check=False)
    text = result.stdout + result.stderr
    assert result.returncode == 0, text
    assert f'checkpoint at update {saved}' in text and f'updates {saved} -> 40' in text
    assert 'is unfinished' not in text and 'collect' not in text.split('resuming')[1]
    assert load_checkpoint(out / 'run' / 'final.pt').step == 40


def test_train_on_a_collection_cut_by_kill_names_recover_then_says_the_round_is_short(
        tmp_path: Path) -> None:
    """Kill -9 mid `zeus collect`: train refuses, naming `zeus recover`; then warns.

    After the recover, train and train --resume run but say the bag was cut short (never a
    silent exit 0 on a cut round).
    """
    config = write_config(tmp_path / 'tiny.yaml', CONFIG)
    out = tmp_path / 'collect'
    bag = out / 'bag_000'
    collect = [sys.executable, '-m', 'zeus_ros.cli', 'collect', '--task', TASK, '--steps',
               str(STEPS), '--out', str(out), '--no-progress']
    with subprocess.Popen(collect, cwd=REPO, stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL) as proc:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if (bag / 'bag_000.mcap').is_file() and (bag / 'bag_000.mcap').stat().st_size > 1e6:
                os.kill(proc.pid, signal.SIGKILL)
                break
            time.sleep(0.05)
        assert proc.wait(30) == -signal.SIGKILL, 'the collection ended before the kill'

    def train(*extra: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, '-m', 'zeus_ros.cli', 'train', '--bags', str(bag), '--config',
             str(config), '--out', str(tmp_path / 'run'), '--no-progress', *extra],
            cwd=REPO, capture_output=True, text=True, timeout=300, check=False)

    refused = train()
    assert refused.returncode == 2 and f'zeus recover {bag}' in refused.stderr, refused.stderr
    assert refused.stderr.count('\n') == 1
    assert subprocess.run([sys.executable, '-m', 'zeus_ros.cli', 'recover', str(bag)],
                          cwd=REPO, capture_output=True, timeout=60).returncode == 0
    for extra in ((), ('--resume', '--updates', '6')):
        result = train(*extra)
        assert result.returncode == 0, result.stderr
        assert f'cut short by a crash: {bag} (recovered)' in result.stdout, result.stdout


def test_loop_resume_after_kill_between_checkpoint_and_final_writes_the_final(
        tmp_path: Path) -> None:
    """Kill between a round's last two writes: --resume writes final.pt, not 'done'.

    The round ends by writing checkpoint.pt, then final.pt; a kill between them leaves
    checkpoint.pt at the round's total and no final.pt (here removed: the same files on disk).
    """
    from zeus_ros.learning.checkpoint import load_checkpoint

    config = write_config(tmp_path / 'tiny.yaml', CONFIG)
    out = tmp_path / 'loop'
    argv = [sys.executable, '-m', 'zeus_ros.cli', 'loop', '--task', TASK, '--config',
            str(config), '--out', str(out), '--rounds', '1', '--random-steps', '400',
            '--updates', '4', '--no-eval', '--no-progress']
    subprocess.run(argv, cwd=REPO, capture_output=True, timeout=300, check=True)
    final = out / 'run' / 'final.pt'
    final.unlink()
    result = subprocess.run([*argv, '--resume'], cwd=REPO, capture_output=True, text=True,
                            timeout=300, check=False)
    text = result.stdout + result.stderr
    assert result.returncode == 0, text
    assert f'trained to update 4, but {final} is missing' in text, text
    assert 'collect' not in text.split('resuming')[1]
    assert load_checkpoint(final).step == 4
