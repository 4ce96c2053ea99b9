"""The README's main job: `zeus demo` runs the live system twice, context live and frozen."""

from __future__ import annotations

from pathlib import Path
import subprocess

import pytest

from zeus_ros.cli.demo import DEFAULT_TASK, default_checkpoint
from zeus_ros.offline.evaluation.metrics import read_csv

from ros_harness import fresh_domain_id, python_module, require_ros, ros_environment


@pytest.mark.ros
def test_demo_compares_the_live_and_the_frozen_context_on_one_schedule(tmp_path: Path) -> None:
    """Both runs log the same schedule, the second with a frozen policy; the table sums both.

    Exit 0, steps.csv and inspection.png of each run, the policy of the second run says its
    context is frozen.
    """
    require_ros()
    assert default_checkpoint(DEFAULT_TASK).is_file()
    out = tmp_path / 'demo'
    done = subprocess.run(python_module('zeus_ros.cli.demo', '--steps', '60', '--seeds', '1',
                                        '--out', str(out)),
                          env=ros_environment(fresh_domain_id()), capture_output=True,
                          text=True, timeout=360, check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    live, frozen = read_csv(out / 'steps.csv'), read_csv(out / 'frozen' / 'steps.csv')
    assert len(live) >= 55 and len(frozen) >= 55
    assert [r['true_motor_bias'] for r in live[:55]] == [
        r['true_motor_bias'] for r in frozen[:55]]
    assert 'context FROZEN' in done.stdout + done.stderr
    table = done.stdout.split('value of adaptation:')[1]
    assert 'live - frozen' in table and '\n all ' in table
    assert (out / 'inspection.png').is_file() and (out / 'frozen' / 'inspection.png').is_file()
    # The zoo checkpoint carries its read-out and its train-mean context: nothing is calibrated
    # or measured at start, and the estimator publishes the estimate in the bias's units.
    assert 'calibrating' not in done.stdout and 'measuring the training-mean' not in done.stdout
    assert sum(bool(r.get('estimated_motor_bias')) for r in live) >= 50
    # The paired value of adaptation: a sentence, a table and a picture.
    assert 'Adapting earned' in done.stdout and 'segments over 1 schedule seed' in done.stdout
    rows = read_csv(out / 'value_of_adaptation.csv')
    assert len(rows) >= 2 and {'return_live', 'return_frozen', 'gain'} <= set(rows[0])
    assert (out / 'value_of_adaptation.png').is_file()
    # The demo's viewer is one of the nodes sim_bridge waits for, and it takes the steps only
    # once it hears the estimator: every step of both runs has its context.
    assert all(r['psi'] for r in live) and all(r['psi'] for r in frozen)


@pytest.mark.ros
def test_the_pixel_demo_runs_the_zoo_pixel_checkpoint_on_rendered_frames(tmp_path: Path) -> None:
    """`zeus demo --obs pixels`: sim_bridge renders, the zoo's pixel pair acts, live and frozen.

    The zoo pixel checkpoint carries its read-out and train-mean psi: nothing is calibrated.
    """
    require_ros()
    out = tmp_path / 'demo'
    done = subprocess.run(python_module('zeus_ros.cli.demo', '--obs', 'pixels', '--steps', '40',
                                        '--seeds', '1', '--out', str(out)),
                          env=ros_environment(fresh_domain_id()), capture_output=True,
                          text=True, timeout=300, check=False)
    text = done.stdout + done.stderr
    assert done.returncode == 0, text[-3000:]
    assert 'pixels_student.pt' in text and 'pixels=True' in text
    assert 'calibrating' not in text and 'measuring the training-mean' not in text
    live, frozen = read_csv(out / 'steps.csv'), read_csv(out / 'frozen' / 'steps.csv')
    assert len(live) >= 35 and len(frozen) >= 35
    assert all(r['psi'] for r in live) and 'context FROZEN' in text
    assert (out / 'value_of_adaptation.csv').is_file()


def test_short_episodes_switch_mid_episode_and_long_ones_every_150_steps() -> None:
    """The demo's schedule follows the task's episode length (no per-task special case)."""
    from zeus_ros.cli.demo import schedule_lengths

    assert schedule_lengths('Cheetah-Run-v1') == (20, 400)  # 40-step episodes
    assert schedule_lengths('Cheetah-Bias-v0') == (20, 400)
    assert schedule_lengths('Cheetah-Run-v0') == (150, 2000)  # 500-step episodes


def test_a_family_without_a_zoo_checkpoint_is_refused_in_one_line() -> None:
    """`zeus demo --task Walker-Walk-v0` names the families that have one; nothing starts."""
    done = subprocess.run(python_module('zeus_ros.cli.demo', '--task', 'Walker-Walk-v0'),
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2
    assert 'has no zoo checkpoint (families with one: Cheetah-Run-v1, Cheetah-Motor-v0, ' \
        'Cheetah-Bias-v0)' in done.stderr
    assert 'Traceback' not in done.stderr


def test_sim_bridge_waits_for_the_demo_viewer_which_waits_for_the_answers() -> None:
    """The viewer is named among sim_bridge's observers; it expects every answer of the group."""
    import argparse

    from zeus_ros.cli.demo import VIEWER, build_nodes, viewer_expects

    args = argparse.Namespace(task=DEFAULT_TASK, steps=60, seed=0, every=20, record=False,
                              pixels=False)
    nodes = {node.name: node.argv for node in build_nodes(args, default_checkpoint(DEFAULT_TASK))}
    bridge = ' '.join(nodes['sim_bridge'])
    assert f"observers:=['context_estimator','policy','{VIEWER}']" in bridge
    assert 'min_observers:=3' in bridge
    assert viewer_expects(['sim_bridge', 'context_estimator', 'policy']) == [
        'zeus/step', 'zeus/context', 'zeus/action', 'zeus/context_truth']
    assert viewer_expects(['sim_bridge', 'policy']) == [
        'zeus/step', 'zeus/action', 'zeus/context_truth']
