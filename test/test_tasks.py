"""The contextual MuJoCo tasks: every context parameter has a measured physical effect."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim_bridge.cheetah import CheetahRunTask, CheetahVelocityTask
from sim_bridge.dmc_base import DmcTask
from sim_bridge.finger import FingerSpinTask, fingertip_radius
from sim_bridge.registry import TASK_NAMES, make_task
from sim_bridge.walker import WalkerFootTask, WalkerFrictionTask


def _body_mass(task: DmcTask, body: str) -> float:
    return float(task.model.body(body).mass[0])


def _xpos(task: DmcTask, body: str) -> np.ndarray:
    return task.data.xpos[task.model.body(body).id].copy()


def test_longer_torso_moves_the_thighs_apart_and_adds_torso_mass() -> None:
    """A longer cheetah torso puts the hips further apart and makes the torso heavier."""
    short = CheetahRunTask(seed=0, context={'torso_length': 0.5})
    long = CheetahRunTask(seed=0, context={'torso_length': 1.0})
    for task in (short, long):
        mujoco.mj_forward(task.model, task.data)
    gap_short = np.linalg.norm(_xpos(short, 'fthigh') - _xpos(short, 'bthigh'))
    gap_long = np.linalg.norm(_xpos(long, 'fthigh') - _xpos(long, 'bthigh'))
    assert gap_short == pytest.approx(1.0)
    assert gap_long == pytest.approx(2.0)
    assert _body_mass(long, 'torso') > 1.5 * _body_mass(short, 'torso')
    assert long.model.body_subtreemass[1] > short.model.body_subtreemass[1]


def test_default_cheetah_keeps_the_suite_masses() -> None:
    """Replacing settotalmass by a density leaves the default cheetah's masses unchanged."""
    from sim_bridge.model_edit import load_suite_spec

    with pytest.warns(UserWarning, match='settotalmass'):
        suite = load_suite_spec('cheetah.xml', light_textures=True).compile()
    ours = CheetahRunTask(seed=0).model
    np.testing.assert_allclose(ours.body_mass, suite.body_mass, rtol=1e-9)
    np.testing.assert_allclose(ours.body_inertia, suite.body_inertia, rtol=1e-9)


def _slide_after_push(friction: float) -> float:
    """How far the left foot of a standing walker slides in 0.2 s after a 1.5 m/s push."""
    task = WalkerFrictionTask(seed=0, context={'friction': friction})
    task.reset()
    model, data = task.model, task.data
    mujoco.mj_resetData(model, data)  # upright at qpos0, feet on the floor
    data.qvel[model.joint('rootx').dofadr[0]] = 1.5
    mujoco.mj_forward(model, data)
    foot = model.body('left_foot').id
    start = data.xpos[foot, 0]
    for _ in range(4):
        task.step(np.zeros(task.action_dim))
    return float(data.xpos[foot, 0] - start)


def test_lower_ground_friction_lets_the_walker_slide_further() -> None:
    """Under the same push a walker on slippery ground slides further than on grippy ground."""
    slippery, grippy = _slide_after_push(0.05), _slide_after_push(2.0)
    assert slippery > 0.15
    assert slippery > 4 * grippy


def test_friction_is_the_floor_contact_friction() -> None:
    """The context value is the friction the solver uses for foot-floor contacts."""
    task = WalkerFrictionTask(seed=0, context={'friction': 0.3})
    task.reset()
    for _ in range(20):
        task.step(np.zeros(task.action_dim))
    assert task.data.ncon > 0
    frictions = task.data.contact.friction[: task.data.ncon, 0]
    np.testing.assert_allclose(frictions, 0.3)


def test_longer_feet_are_longer_and_heavier_on_both_sides() -> None:
    """foot_length changes both foot capsules, their masses and inertias alike."""
    short = WalkerFootTask(seed=0, context={'foot_length': 0.06})
    long = WalkerFootTask(seed=0, context={'foot_length': 0.18})
    for foot in ('left_foot', 'right_foot'):
        assert short.model.geom(foot).size[1] == pytest.approx(0.06)
        assert long.model.geom(foot).size[1] == pytest.approx(0.18)
        assert _body_mass(long, foot) > 1.5 * _body_mass(short, foot)
        assert long.model.body(foot).inertia.max() > short.model.body(foot).inertia.max()
    assert _body_mass(long, 'left_foot') == pytest.approx(_body_mass(long, 'right_foot'))


def test_bigger_finger_changes_the_fingertip_mass_and_the_image() -> None:
    """finger_size scales the colliding fingertip: its radius, the distal mass and the pixels."""
    small = FingerSpinTask(seed=3, context={'finger_size': 0.025})
    big = FingerSpinTask(seed=3, context={'finger_size': 0.35})
    try:
        assert small.model.geom('fingertip').size[0] == pytest.approx(0.03)
        assert big.model.geom('fingertip').size[0] == pytest.approx(fingertip_radius(0.35))
        assert _body_mass(big, 'distal') > 2 * _body_mass(small, 'distal')
        small.reset(seed=3)
        big.reset(seed=3)
        mujoco.mj_resetData(big.model, big.data)
        mujoco.mj_resetData(small.model, small.data)
        for task in (small, big):
            mujoco.mj_forward(task.model, task.data)
        image_small, image_big = small.render(), big.render()
        assert image_small.shape == (84, 84, 3)
        assert image_small.dtype == np.uint8
        changed = np.any(image_small != image_big, axis=-1).mean()
        assert changed > 0.01
    finally:
        small.close()
        big.close()


def test_target_velocity_changes_only_the_reward() -> None:
    """The same motion earns different rewards under different target velocities."""
    slow = CheetahVelocityTask(seed=5, context={'target_velocity': 0.0})
    fast = CheetahVelocityTask(seed=5, context={'target_velocity': 3.0})
    slow.reset()
    fast.reset()
    rng = np.random.default_rng(0)
    for _ in range(5):
        action = rng.uniform(-1, 1, slow.action_dim)
        out_slow, out_fast = slow.step(action), fast.step(action)
        np.testing.assert_array_equal(out_slow.state, out_fast.state)
        assert out_slow.reward != pytest.approx(out_fast.reward)


def test_mid_episode_context_change_keeps_the_physical_state() -> None:
    """Switching the geometry mid-episode carries qpos, qvel and time into the new model."""
    task = CheetahRunTask(seed=1)
    task.reset()
    for _ in range(10):
        task.step(np.full(task.action_dim, 0.5))
    old_model = task.model
    qpos, qvel, time = task.data.qpos.copy(), task.data.qvel.copy(), task.data.time
    task.set_context({'torso_length': 0.8})
    assert task.model is not old_model
    np.testing.assert_array_equal(task.data.qpos, qpos)
    np.testing.assert_array_equal(task.data.qvel, qvel)
    assert task.data.time == time
    assert task.context == {'torso_length': 0.8}
    assert task.step(np.zeros(task.action_dim)).context == {'torso_length': 0.8}


def test_returning_to_a_context_reuses_the_compiled_model() -> None:
    """The LRU cache compiles each geometry once while it stays in the cache."""
    task = WalkerFootTask(seed=0)
    task.reset()
    before = task.cache.compiles
    for value in (0.12, 0.1, 0.12, 0.1):
        task.set_context({'foot_length': value})
    assert task.cache.compiles == before + 1


@pytest.mark.parametrize(
    ('domain', 'cls'),
    [('cheetah', CheetahRunTask), ('walker', WalkerFrictionTask), ('finger', FingerSpinTask)],
)
def test_observation_and_reward_match_dm_control(domain: str, cls: type[DmcTask]) -> None:
    """At the default context our observation and reward equal the suite's for the same state."""
    from dm_control import suite

    env = suite.load(domain, {'cheetah': 'run', 'walker': 'walk', 'finger': 'spin'}[domain])
    env.reset()
    physics = env.physics
    task = cls(seed=2)
    task.reset()
    rng = np.random.default_rng(0)
    for _ in range(3):
        task.step(rng.uniform(-1, 1, task.action_dim))
    with physics.reset_context():
        physics.data.qpos[:] = task.data.qpos
        physics.data.qvel[:] = task.data.qvel
    expected = np.concatenate(
        [np.atleast_1d(v).ravel() for v in env.task.get_observation(physics).values()]
    )
    np.testing.assert_allclose(task._observation(task.model, task.data), expected, atol=1e-9)
    assert task._reward(task.model, task.data, np.zeros(task.action_dim)) == pytest.approx(
        env.task.get_reward(physics)
    )


def test_episode_ends_after_episode_length_and_needs_a_reset() -> None:
    """The last observation comes at episode_length; stepping past it is an error."""
    task = CheetahVelocityTask(seed=0)
    assert task.reset().first
    results = [task.step(np.zeros(task.action_dim)) for _ in range(task.episode_length)]
    assert [r.last for r in results].count(True) == 1
    assert results[-1].last
    with pytest.raises(RuntimeError, match='reset'):
        task.step(np.zeros(task.action_dim))


@pytest.mark.parametrize(
    ('context', 'fragment'),
    [({'torso_len': 0.5}, 'unknown context parameter'), ({'torso_length': 9.0}, 'outside')],
)
def test_bad_context_is_rejected_with_the_reason(context: dict, fragment: str) -> None:
    """Unknown names and out-of-range values raise ValueError naming the problem."""
    task = CheetahRunTask(seed=0)
    with pytest.raises(ValueError, match=fragment):
        task.set_context(context)


def test_unknown_task_name_lists_the_valid_names() -> None:
    """make_task refuses an unknown name and lists the registered ones."""
    with pytest.raises(ValueError, match='Cheetah-Run-v0'):
        make_task('Cheetah-Fly-v0')
    assert 'Sawyer-Peg-v0' in TASK_NAMES
