"""Action validation and the shared ScheduledEnv step loop."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from sim_bridge.actions import ActionStatus, check_action
from sim_bridge.env import ScheduledEnv
from sim_bridge.registry import make_task
from sim_bridge.schedules import schedule_from_config

LOW, HIGH = -np.ones(3), np.ones(3)


def test_status_codes_match_the_message_constants() -> None:
    """ActionStatus equals StepFeedback's ACTION_* constants in the .msg file."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / 'msg_defs' / 'msg' /
            'StepFeedback.msg').read_text()
    for status in ActionStatus:
        assert f'uint8 ACTION_{status.name}={int(status)}' in text


def test_valid_action_passes_unchanged() -> None:
    """An in-range action is applied as sent."""
    check = check_action([0.5, -0.5, 1.0], LOW, HIGH)
    assert check.status == ActionStatus.OK and check.applied.tolist() == [0.5, -0.5, 1.0]


def test_out_of_range_values_are_clipped_and_named() -> None:
    """Values beyond the bounds are clipped; the reason names their indices."""
    check = check_action([2.0, 0.0, -3.0], LOW, HIGH)
    assert check.status == ActionStatus.CLIPPED
    assert check.applied.tolist() == [1.0, 0.0, -1.0]
    assert '[0, 2]' in check.reason


@pytest.mark.parametrize(('values', 'fragment'), [
    ([0.0, 0.0], '2 values'), ([0.0, np.nan, 0.0], 'NaN/Inf at index [1]'),
    ([np.inf, 0.0, 0.0], 'index [0]'),
])
def test_malformed_actions_are_rejected_with_the_safe_action(values: list, fragment: str) -> None:
    """Wrong length or non-finite values give the safe action and a reason."""
    check = check_action(values, LOW, HIGH)
    assert check.status == ActionStatus.REJECTED
    assert check.applied.tolist() == [0.0, 0.0, 0.0]
    assert fragment in check.reason


def test_context_follows_the_schedule_across_a_mid_episode_switch() -> None:
    """The context of o_k is the schedule's value for k; the switch keeps the episode going."""
    task = make_task('Cheetah-Run-v0', seed=0)
    env = ScheduledEnv(task, schedule_from_config(
        {'kind': 'switch', 'every': 30, 'values': [0.6, 1.2]}, task))
    steps = [env.reset()] + [env.step(np.zeros(6)) for _ in range(70)]
    assert [s.observation.context['torso_length'] for s in steps[28:32]] == [0.6, 0.6, 1.2, 1.2]
    assert [s.segment for s in (steps[29], steps[30], steps[60])] == [0, 1, 2]
    assert not any(s.observation.first for s in steps[1:])
    assert all(s.status == ActionStatus.OK for s in steps[1:])


def test_episodes_roll_over_and_the_clock_keeps_running() -> None:
    """After `last`, step() resets (status NONE); sim time never goes backwards."""
    task = make_task('Cheetah-Run-v1', seed=0)  # 40-step episodes
    env = ScheduledEnv(task, schedule_from_config(None, task))
    steps = [env.reset()] + [env.step(np.zeros(6)) for _ in range(90)]
    assert steps[40].observation.last and steps[40].episode_step == 40
    assert steps[41].observation.first and steps[41].episode == 1
    assert steps[41].status == ActionStatus.NONE and steps[41].applied_action is None
    times = [s.sim_time for s in steps]
    assert all(b > a for a, b in itertools.pairwise(times))
    assert [s.step for s in steps] == list(range(91))


def test_missing_action_times_out_with_the_safe_action() -> None:
    """step(None) applies the safe action and says TIMEOUT."""
    task = make_task('Cheetah-Run-v0', seed=0)
    env = ScheduledEnv(task, schedule_from_config(None, task))
    env.reset()
    result = env.step(None)
    assert result.status == ActionStatus.TIMEOUT
    assert result.applied_action.tolist() == [0.0] * 6


def test_a_continued_run_goes_on_with_the_schedule_where_the_earlier_one_stopped() -> None:
    """schedule_start: one value per episode resumes at the 5th value, indices start at 0."""
    task = make_task('Cheetah-Run-v0', seed=0)
    values = [0.6, 0.7, 0.8, 0.9, 1.0, 1.1]
    schedule = schedule_from_config({'kind': 'switch', 'every_episodes': 1, 'values': values},
                                    task)
    env = ScheduledEnv(task, schedule, schedule_start=(4 * 500, 4))
    first = env.reset()
    assert (first.step, first.episode) == (0, 0)
    assert first.observation.context['torso_length'] == 1.0
    task.close()
