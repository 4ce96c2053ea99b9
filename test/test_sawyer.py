"""Sawyer-Peg-v0: goal context, mid-episode changes, episode length, actions, rendering."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from sim_bridge.families import load_preset
from sim_bridge.presets import SPLITS
from sim_bridge.registry import make_task
from sim_bridge.sawyer import ACTION_SCALE, SawyerPegTask, peg_reward

NEAR = {'goal_x': 0.4495, 'goal_y': 0.0714}
FAR = {'goal_x': 0.6079, 'goal_y': -0.077}


@pytest.fixture
def task() -> Iterator[SawyerPegTask]:
    """A task reset under the NEAR goal, closed afterwards (it may hold a GL context)."""
    sawyer = SawyerPegTask(seed=0, context=NEAR)
    sawyer.reset()
    yield sawyer
    sawyer.close()


def _box_position(task: SawyerPegTask) -> np.ndarray:
    return task.data.xpos[task.model.body('box').id].copy()


def test_goal_context_moves_the_box(task: SawyerPegTask) -> None:
    """The measured box body position follows goal_x/goal_y."""
    task.set_context(FAR)
    np.testing.assert_allclose(_box_position(task)[:2], [FAR['goal_x'], FAR['goal_y']])


def test_goal_context_changes_the_reward_of_the_same_pose(task: SawyerPegTask) -> None:
    """Same motion from the same start, different goal: a different reward, same arm pose."""
    other = SawyerPegTask(context=FAR)
    other.reset()
    near_reward = task.step(np.zeros(3)).reward
    far_reward = other.step(np.zeros(3)).reward
    np.testing.assert_allclose(other.data.qpos, task.data.qpos, atol=1e-9)
    assert near_reward == pytest.approx(peg_reward(task.peg_tip, task.goal))
    assert far_reward == pytest.approx(peg_reward(other.peg_tip, other.goal))
    assert abs(near_reward - far_reward) > 0.1


def test_reward_pays_the_sparse_margin_inside_three_centimetres() -> None:
    """MELD's formula without offset, plus 1 once 5 * distance < 0.15."""
    goal = np.zeros(3)
    outside, inside = np.array([0.031, 0.0, 0.0]), np.array([0.029, 0.0, 0.0])
    shaped = [-(d**2 + np.log10(d**2 + 1e-5)) for d in (0.155, 0.145)]
    assert peg_reward(outside, goal) == pytest.approx(shaped[0])
    assert peg_reward(inside, goal) == pytest.approx(shaped[1] + 1.0)


def test_set_context_mid_episode_keeps_qpos_qvel_and_time(task: SawyerPegTask) -> None:
    """Moving the box does not touch the arm's state or the clock."""
    task.step(np.array([1.0, -1.0, -1.0]))
    before = task.data.qpos.copy(), task.data.qvel.copy(), task.sim_time
    task.set_context(FAR)
    assert np.array_equal(task.data.qpos, before[0])
    assert np.array_equal(task.data.qvel, before[1])
    assert task.sim_time == before[2] > 0.0


def test_episode_is_forty_steps_with_last_on_the_fortieth(task: SawyerPegTask) -> None:
    """`last` is False for 39 steps, True on the 40th; stepping on needs a reset."""
    flags = [task.step(np.zeros(3)).last for _ in range(40)]
    assert flags == [False] * 39 + [True]
    assert task.sim_time == pytest.approx(40 * task.agent_period)
    with pytest.raises(RuntimeError):
        task.step(np.zeros(3))


@pytest.mark.parametrize('axis', [0, 1, 2])
def test_action_moves_the_peg_in_the_commanded_direction(task: SawyerPegTask, axis: int) -> None:
    """A unit action on one axis moves the tip about ACTION_SCALE along it, little elsewhere."""
    start = task.peg_tip
    action = np.zeros(3)
    action[axis] = -1.0 if axis == 2 else 1.0
    moved = task.step(action).state[-3:] - start
    assert moved[axis] * action[axis] == pytest.approx(ACTION_SCALE, rel=0.1)
    assert np.linalg.norm(np.delete(moved, axis)) < 0.1 * ACTION_SCALE


def test_state_is_joints_velocities_and_tip_without_the_goal(task: SawyerPegTask) -> None:
    """17 float64 values; two goals give the same state for the same motion."""
    other = SawyerPegTask(context=FAR)
    other.reset()
    action = np.array([0.3, -0.2, -0.5])
    a, b = task.step(action).state, other.step(action).state
    assert a.dtype == np.float64 and a.shape == (task.state_dim,) == (17,)
    np.testing.assert_allclose(a, b, atol=1e-9)


@pytest.mark.slow
def test_render_is_84x84_rgb_and_shows_the_box_move(task: SawyerPegTask) -> None:
    """The fixed camera sees the box: moving it changes the frame."""
    before = task.render()
    task.set_context(FAR)
    after = task.render()
    assert before.shape == (84, 84, 3) and before.dtype == np.uint8
    assert np.abs(before.astype(int) - after.astype(int)).sum(axis=2).astype(bool).sum() > 20


def test_registry_builds_the_task_and_accepts_every_preset_goal() -> None:
    """make_task('Sawyer-Peg-v0') works and every train/interp./extrap. goal is in range."""
    sawyer = make_task('Sawyer-Peg-v0', seed=1)
    goals = [goal for split in SPLITS for goal in load_preset('Sawyer-Peg-v0', split)]
    assert isinstance(sawyer, SawyerPegTask) and len(goals) == 16
    for goal in goals:
        sawyer.set_context(goal)
        assert sawyer.context == goal


def test_out_of_range_goal_is_rejected() -> None:
    """A goal off the table raises ValueError naming the parameter."""
    with pytest.raises(ValueError, match='goal_x'):
        SawyerPegTask(context={'goal_x': 2.0})


def test_scripted_insertion_reaches_the_sparse_margin(task: SawyerPegTask) -> None:
    """Hovering over the hole and descending puts the tip in it within one episode."""
    rewards = []
    for _ in range(task.episode_length):
        tip, goal = task.peg_tip, task.goal
        aligned = np.linalg.norm(tip[:2] - goal[:2]) < 0.003
        target = goal if aligned else np.array([goal[0], goal[1], 0.08])
        rewards.append(task.step(np.clip((target - tip) / ACTION_SCALE, -1.0, 1.0)).reward)
    assert np.linalg.norm(task.peg_tip - task.goal) < 0.03
    assert rewards[-1] > 1.0 + rewards[0]
