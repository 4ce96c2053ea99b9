"""Context schedules: values, reproducibility, bounds and config errors."""

from __future__ import annotations

import itertools

import pytest

from sim_bridge.registry import make_task
from sim_bridge.schedules import schedule_from_config


@pytest.fixture(scope='module')
def cheetah() -> object:
    """One Cheetah-Run-v0 task for the whole module (schedules only read its specs)."""
    return make_task('Cheetah-Run-v0')


def values(schedule: object, steps: range, episode: int = 0) -> list[float]:
    """The torso length the schedule gives for each step."""
    return [schedule.value_at(step, episode)['torso_length'] for step in steps]


def test_constant_gives_one_value_and_defaults_fill_the_rest(cheetah: object) -> None:
    """A constant schedule returns its value at every step."""
    schedule = schedule_from_config({'kind': 'constant', 'value': 0.8}, cheetah)
    assert set(values(schedule, range(0, 5000, 97))) == {0.8}
    assert schedule_from_config(None, cheetah).value_at(10, 3) == {'torso_length': 0.5}


def test_switch_every_n_steps_cycles_through_the_list(cheetah: object) -> None:
    """Switching every 10 steps walks the list in order and wraps around."""
    schedule = schedule_from_config(
        {'kind': 'switch', 'every': 10, 'values': [0.6, 1.0, 1.4]}, cheetah)
    assert values(schedule, range(0, 60, 10)) == [0.6, 1.0, 1.4, 0.6, 1.0, 1.4]
    assert values(schedule, range(10, 20)) == [1.0] * 10


def test_switch_at_episode_boundaries_ignores_the_step(cheetah: object) -> None:
    """every_episodes switches only when the episode index changes."""
    schedule = schedule_from_config(
        {'kind': 'switch', 'every_episodes': 2, 'values': [0.6, 1.0]}, cheetah)
    assert [schedule.value_at(999, e)['torso_length'] for e in range(6)] == \
        [0.6, 0.6, 1.0, 1.0, 0.6, 0.6]


def test_sampled_switch_is_reproducible_with_its_seed(cheetah: object) -> None:
    """The same seed gives the same sequence; another seed a different one."""
    config = {'kind': 'switch', 'every': 5, 'values': 'train', 'order': 'sample'}
    first = values(schedule_from_config(config, cheetah, seed=4), range(0, 500, 5))
    again = values(schedule_from_config(config, cheetah, seed=4), range(0, 500, 5))
    other = values(schedule_from_config(config, cheetah, seed=5), range(0, 500, 5))
    assert first == again and first != other
    assert len(set(first)) > 4


def test_preset_splits_are_the_paper_tables_and_disjoint(cheetah: object) -> None:
    """The train preset holds no extrapolation value (the paper's lists overlap)."""
    from sim_bridge.families import load_preset

    train = {v['torso_length'] for v in load_preset('Cheetah-Run-v0', 'train')}
    extrapolation = {v['torso_length'] for v in load_preset('Cheetah-Run-v0', 'extrapolation')}
    assert 0.6 in train and 1.15 in train and 1.5 in extrapolation
    assert not train & extrapolation
    assert all(v < min(train) or v > max(train) for v in extrapolation)


def test_ramp_and_sinusoid_stay_inside_the_range(cheetah: object) -> None:
    """Drift covers [low, high] smoothly and never leaves it."""
    ramp = schedule_from_config(
        {'kind': 'drift', 'shape': 'ramp', 'low': 0.6, 'high': 1.2, 'period': 100}, cheetah)
    ramp_values = values(ramp, range(100))
    assert ramp_values[0] == pytest.approx(0.6)
    assert ramp_values[50] == pytest.approx(0.9)
    assert all(b > a for a, b in itertools.pairwise(ramp_values))
    sine = schedule_from_config(
        {'kind': 'drift', 'low': 0.6, 'high': 1.2, 'period': 40}, cheetah)
    sine_values = values(sine, range(200))
    assert min(sine_values) >= 0.6 and max(sine_values) <= 1.2
    assert sine_values[10] == pytest.approx(1.2) and sine_values[30] == pytest.approx(0.6)


def test_random_walk_is_bounded_and_reproducible(cheetah: object) -> None:
    """A long random walk stays in bounds, moves, and repeats with its seed."""
    config = {'kind': 'random_walk', 'low': 0.4, 'high': 1.4, 'step_size': 0.2, 'every': 2}
    walk = values(schedule_from_config(config, cheetah, seed=1), range(5000))
    assert min(walk) >= 0.4 and max(walk) <= 1.4
    assert walk[0] == walk[1] and len(set(walk)) > 1000
    assert walk == values(schedule_from_config(config, cheetah, seed=1), range(5000))


@pytest.mark.parametrize(('config', 'fragment'), [
    ({'kind': 'wobble'}, "kind 'wobble'"),
    ({'kind': 'switch', 'values': [0.6]}, "'every'"),
    ({'kind': 'switch', 'every': 10, 'values': [0.6], 'speed': 3}, "['speed']"),
    ({'kind': 'switch', 'every': 10, 'values': 'holdout'}, "'holdout'"),
    ({'kind': 'constant', 'value': 9.0}, 'torso_length=9.0 is outside'),
    ({'kind': 'drift', 'low': 1.0, 'high': 0.5, 'period': 10}, 'low (1.0)'),
    ({'kind': 'constant', 'context': {'gravity': 3.0}}, "'gravity'"),
])
def test_bad_config_names_the_key(cheetah: object, config: dict, fragment: str) -> None:
    """Each config mistake is a ValueError that names what is wrong."""
    with pytest.raises(ValueError) as error:
        schedule_from_config(config, cheetah)
    assert fragment in str(error.value)
