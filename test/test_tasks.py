"""Every task's context measurably changes the physics, and the default models match the suite."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
import itertools
import os

import mujoco
import numpy as np
import pytest

from sim_bridge.dmc_base import DmcTask
from sim_bridge.families import load_preset
from sim_bridge.finger import fingertip_radius
from sim_bridge.presets import SPLITS
from sim_bridge.registry import TASK_NAMES, make_task

os.environ.setdefault('MUJOCO_GL', 'egl')

Build = Callable[..., DmcTask]
DMC_TASKS = ('Cheetah-Run-v0', 'Cheetah-Run-v1', 'Cheetah-Motor-v0', 'Cheetah-Bias-v0',
             'Walker-Walk-v0', 'Walker-Walk-v1', 'Finger-Spin-v0')


@pytest.fixture
def build() -> Iterator[Build]:
    """Factory for tasks whose renderers are closed at teardown (EGL contexts are scarce)."""
    made: list[DmcTask] = []

    def _build(name: str, seed: int | None = 0, **context: float) -> DmcTask:
        task = make_task(name, seed=seed, context=context or None)
        assert isinstance(task, DmcTask)
        made.append(task)
        return task

    yield _build
    for task in made:
        task.close()


def _forward_at_qpos0(task: DmcTask) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The task's model and data in the reference pose, kinematics computed."""
    model, data = task.model, task.data
    mujoco.mj_resetData(model, data)
    mujoco.mj_forward(model, data)
    return model, data


def _run(task: DmcTask, actions: np.ndarray) -> tuple[list[np.ndarray], list[float]]:
    """States and rewards of an episode started with seed 0 and driven by `actions`."""
    states, rewards = [task.reset(seed=0).state], []
    for action in actions:
        result = task.step(action)
        states.append(result.state)
        rewards.append(result.reward)
    return states, rewards


# --- Cheetah-Run-v0: torso_length ----------------------------------------------------------------

@pytest.mark.parametrize('length', [0.3, 0.5, 1.5])
def test_torso_length_sets_the_distance_between_the_thighs(build: Build, length: float) -> None:
    """The hips sit at the torso ends: bthigh and fthigh are 2 L apart along the body axis."""
    model, data = _forward_at_qpos0(build('Cheetah-Run-v0', torso_length=length))
    gap = data.xpos[model.body('fthigh').id] - data.xpos[model.body('bthigh').id]
    np.testing.assert_allclose(gap, [2 * length, 0.0, 0.0], atol=1e-12)


def test_longer_torso_is_heavier_with_more_pitch_inertia(build: Build) -> None:
    """Torso mass and inertia grow with its length; the legs keep their masses."""
    models = [build('Cheetah-Run-v0', torso_length=length).model for length in (0.3, 0.5, 1.5)]
    torso = models[0].body('torso').id
    masses = [float(m.body_mass[torso]) for m in models]
    pitch = [float(m.body_inertia[torso].max()) for m in models]
    assert masses[0] < masses[1] < masses[2]
    assert pitch[0] < pitch[1] < pitch[2]
    for leg in ('bthigh', 'bfoot', 'fthigh', 'ffoot'):
        leg_masses = {float(m.body_mass[m.body(leg).id]) for m in models}
        assert len(leg_masses) == 1, (leg, leg_masses)


def test_torso_subtree_mass_is_the_sum_of_the_body_masses(build: Build) -> None:
    """body_subtreemass of the torso is the total mass of the recompiled cheetah."""
    model = build('Cheetah-Run-v0', torso_length=1.4).model
    torso = model.body('torso').id
    assert model.body_subtreemass[torso] == pytest.approx(float(model.body_mass[1:].sum()))
    assert model.body_subtreemass[torso] > 14.0 + 1.0  # heavier than the suite's 14 kg


def test_default_cheetah_has_the_suite_masses(build: Build) -> None:
    """Replacing settotalmass by a density keeps every default body mass of the suite."""
    from dm_control import suite

    env = suite.load('cheetah', 'run', task_kwargs={'random': 0})
    np.testing.assert_allclose(
        build('Cheetah-Run-v0').model.body_mass, env.physics.model.body_mass, rtol=1e-12)


# --- Walker-Walk-v0: friction --------------------------------------------------------------------

def _stand_on_floor(task: DmcTask) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The upright walker at qpos0, lowered until both feet just touch the floor."""
    model, data = _forward_at_qpos0(task)
    feet = [model.geom(name).id for name in ('left_foot', 'right_foot')]
    lowest = min(data.geom_xpos[g, 2] - model.geom_size[g, 0] for g in feet)
    data.qpos[0] = -lowest - 1e-4  # rootz: 0.1 mm penetration, so the contacts exist
    mujoco.mj_forward(model, data)
    return model, data


def _foot_slide(task: DmcTask, push: float = 1.0, steps: int = 40) -> float:
    """How far the left foot slides in 0.1 s after the standing walker is shoved forward."""
    model, data = _stand_on_floor(task)
    foot = model.body('left_foot').id
    start = float(data.xpos[foot, 0])
    data.qvel[1] = push  # rootx velocity of the whole walker
    mujoco.mj_step(model, data, nstep=steps)
    return float(data.xpos[foot, 0]) - start


def test_lower_friction_lets_a_foot_slide_further(build: Build) -> None:
    """The same shove slides the foot further on a slipperier floor (monotone in friction)."""
    slides = [_foot_slide(build('Walker-Walk-v0', friction=mu)) for mu in (0.05, 0.3, 0.7, 1.9)]
    assert all(a > b for a, b in itertools.pairwise(slides)), slides
    assert slides[0] > 3 * slides[-1], slides


@pytest.mark.parametrize('mu', [0.3, 1.9])
def test_floor_friction_sets_every_foot_contact(build: Build, mu: float) -> None:
    """Below or above the walker's own 0.7, the contact friction is the context value."""
    model, data = _stand_on_floor(build('Walker-Walk-v0', friction=mu))
    assert data.ncon >= 2
    floor = model.geom('floor').id
    for contact in data.contact[:data.ncon]:
        assert floor in (contact.geom1, contact.geom2)
        assert contact.friction[0] == pytest.approx(mu)


# --- Walker-Walk-v1: foot_length -----------------------------------------------------------------

@pytest.mark.parametrize('length', [0.03, 0.21])
def test_foot_length_sets_both_foot_capsules(build: Build, length: float) -> None:
    """Both foot capsules get the half-length; their radius stays the suite's 0.05."""
    model = build('Walker-Walk-v1', foot_length=length).model
    for name in ('left_foot', 'right_foot'):
        np.testing.assert_allclose(model.geom(name).size[:2], [0.05, length])


def test_longer_feet_are_heavier_and_symmetric(build: Build) -> None:
    """Foot mass and inertia grow with the length, identically on the left and the right."""
    masses = []
    for length in (0.03, 0.1, 0.21):
        model = build('Walker-Walk-v1', foot_length=length).model
        left, right = model.body('left_foot').id, model.body('right_foot').id
        assert model.body_mass[left] == model.body_mass[right]
        np.testing.assert_array_equal(model.body_inertia[left], model.body_inertia[right])
        masses.append(float(model.body_mass[left]))
    assert masses[0] < masses[1] < masses[2]


# --- Finger-Spin-v0: finger_size -----------------------------------------------------------------

def test_bigger_finger_grows_the_fingertip_and_the_distal_mass(build: Build) -> None:
    """The fingertip radius follows the documented map; the distal link gets heavier."""
    masses = []
    for size in (0.01, 0.025, 0.5):
        model = build('Finger-Spin-v0', finger_size=size).model
        assert model.geom('fingertip').size[0] == pytest.approx(fingertip_radius(size))
        assert model.site('touchtop').size[0] == pytest.approx(size)
        masses.append(float(model.body_mass[model.body('distal').id]))
    assert fingertip_radius(0.025) == pytest.approx(0.03)  # the suite's fingertip at default
    assert masses[0] < masses[1] < masses[2]


@pytest.mark.slow
def test_bigger_finger_changes_the_rendered_image(build: Build) -> None:
    """The same state renders differently once the finger is bigger (it is visible)."""
    task = build('Finger-Spin-v0')
    task.reset(seed=0)
    before = task.render()
    task.set_context({'finger_size': 0.35})
    after = task.render()
    changed = int((before != after).any(axis=-1).sum())
    assert changed > 100, changed


@pytest.mark.slow
def test_switched_context_renders_like_a_task_built_for_it(build: Build) -> None:
    """After a switch the frame is exactly that of a fresh task of the new size, same state."""
    switched = build('Finger-Spin-v0')
    switched.reset(seed=0)
    switched.set_context({'finger_size': 0.2})
    fresh = build('Finger-Spin-v0', finger_size=0.2)
    fresh.reset(seed=0)
    fresh.data.qpos[:] = switched.data.qpos
    fresh.data.qvel[:] = switched.data.qvel
    mujoco.mj_forward(fresh.model, fresh.data)
    np.testing.assert_array_equal(switched.render(), fresh.render())


# --- Cheetah-Run-v1: target_velocity -------------------------------------------------------------

def test_same_motion_earns_another_reward_under_another_target(build: Build) -> None:
    """Identical actions give identical states but different rewards for another target."""
    actions = np.random.default_rng(3).uniform(-1, 1, (20, 6))
    slow_states, slow_rewards = _run(build('Cheetah-Run-v1', target_velocity=0.5), actions)
    fast_states, fast_rewards = _run(build('Cheetah-Run-v1', target_velocity=3.0), actions)
    np.testing.assert_array_equal(np.array(slow_states), np.array(fast_states))
    assert all(a != b for a, b in zip(slow_rewards, fast_rewards, strict=True))


def test_target_reward_is_linear_in_the_target_below_the_speed(build: Build) -> None:
    """Standing still, raising the target by dv costs exactly dv per control step."""
    zero = np.zeros((5, 6))
    _, low = _run(build('Cheetah-Run-v1', target_velocity=1.5), zero)
    _, high = _run(build('Cheetah-Run-v1', target_velocity=3.0), zero)
    repeat = build('Cheetah-Run-v1').action_repeat
    np.testing.assert_allclose(np.subtract(low, high), repeat * 1.5, atol=1e-9)


# --- Cheetah-Motor-v0: motor_gain ---------------------------------------------------------------

@pytest.mark.parametrize('gain', [0.2, 1.0, 1.6])
def test_motor_gain_scales_every_gear_and_nothing_else(build: Build, gain: float) -> None:
    """The gear (torque per unit command) of each motor is the suite's times the gain."""
    suite_model = build('Cheetah-Run-v0').model
    model = build('Cheetah-Motor-v0', motor_gain=gain).model
    np.testing.assert_allclose(model.actuator_gear, suite_model.actuator_gear * gain)
    np.testing.assert_array_equal(model.body_mass, suite_model.body_mass)
    np.testing.assert_array_equal(model.actuator_ctrlrange, suite_model.actuator_ctrlrange)


def test_weaker_motors_move_the_body_less_for_the_same_commands(build: Build) -> None:
    """Same start and commands: joint speeds grow with the gain (the context is dynamics)."""
    actions = np.random.default_rng(4).uniform(-1, 1, (5, 6))
    speeds = []
    for gain in (0.3, 1.0, 1.5):
        states, _ = _run(build('Cheetah-Motor-v0', motor_gain=gain), actions)
        speeds.append(float(np.abs(np.array(states)[1:, -6:]).mean()))  # joint velocities
    assert speeds[0] < speeds[1] < speeds[2]


def test_motor_reward_tracks_two_metres_per_second(build: Build) -> None:
    """Standing still costs |0 - 2| per control step, whatever the motors (plus no action)."""
    for gain in (0.4, 1.1):
        task = build('Cheetah-Motor-v0', motor_gain=gain)
        task.reset(seed=0)
        speed_before = float(task.data.sensor('torso_subtreelinvel').data[0])
        reward = task.step(np.zeros(6)).reward
        assert reward == pytest.approx(-2.0 * task.action_repeat, abs=0.1 + 4 * abs(speed_before))


# --- Cheetah-Bias-v0: motor_bias ---------------------------------------------------------------

@pytest.mark.parametrize('bias', [-0.3, 0.45])
def test_motor_bias_is_a_command_offset_the_policy_can_cancel(build: Build, bias: float) -> None:
    """Commands a under bias b move the body exactly as a + b without it (while |a + b| <= 1).

    So the best command is shifted by the bias itself: the action depends on the context.
    """
    actions = np.random.default_rng(5).uniform(-0.4, 0.4, (8, 6))
    biased, biased_rewards = _run(build('Cheetah-Bias-v0', motor_bias=bias), actions)
    plain, _ = _run(build('Cheetah-Bias-v0', motor_bias=0.0), actions + bias)
    np.testing.assert_allclose(np.array(biased), np.array(plain), atol=1e-9)
    suite = build('Cheetah-Run-v0').model
    model = build('Cheetah-Bias-v0', motor_bias=bias).model
    np.testing.assert_array_equal(model.actuator_gear, suite.actuator_gear)
    np.testing.assert_array_equal(model.body_mass, suite.body_mass)
    cancelled, cancelled_rewards = _run(build('Cheetah-Bias-v0', motor_bias=bias), actions - bias)
    unbiased, _ = _run(build('Cheetah-Bias-v0', motor_bias=0.0), actions)
    np.testing.assert_allclose(np.array(cancelled), np.array(unbiased), atol=1e-9)
    assert biased_rewards != cancelled_rewards


def test_motor_bias_shows_at_rest_but_not_in_the_start_pose(build: Build) -> None:
    """Every bias starts from the same pose; zero commands then turn the joints its way."""
    zero = np.zeros((3, 6))
    joint_speed, starts = {}, {}
    for bias in (-0.3, 0.0, 0.3):
        states, _ = _run(build('Cheetah-Bias-v0', motor_bias=bias), zero)
        starts[bias] = states[0]
        joint_speed[bias] = np.array(states)[1][-6:]  # joint velocities after one step
    assert (joint_speed[-0.3] < joint_speed[0.0]).all()
    assert (joint_speed[0.0] < joint_speed[0.3]).all()
    np.testing.assert_array_equal(starts[-0.3], starts[0.0])
    np.testing.assert_array_equal(starts[0.3], starts[0.0])


# --- shared behaviour ----------------------------------------------------------------------------

@pytest.mark.parametrize(('name', 'parameter', 'value'), [
    ('Cheetah-Run-v0', 'torso_length', 1.2),
    ('Cheetah-Motor-v0', 'motor_gain', 0.3),
    ('Cheetah-Bias-v0', 'motor_bias', -0.4),
    ('Walker-Walk-v1', 'foot_length', 0.18),
    ('Finger-Spin-v0', 'finger_size', 0.2),
])
def test_geometry_switch_mid_episode_keeps_the_physical_state(
    build: Build, name: str, parameter: str, value: float
) -> None:
    """set_context swaps the model but keeps qpos, qvel and time bit for bit."""
    task = build(name)
    _run(task, np.random.default_rng(1).uniform(-1, 1, (10, task.action_dim)))
    old_model = task.model
    qpos, qvel, time = task.data.qpos.copy(), task.data.qvel.copy(), task.sim_time
    task.set_context({parameter: value})
    assert task.model is not old_model
    np.testing.assert_array_equal(task.data.qpos, qpos)
    np.testing.assert_array_equal(task.data.qvel, qvel)
    assert task.sim_time == time
    assert np.isfinite(task.step(np.zeros(task.action_dim)).state).all()


@pytest.mark.parametrize(('name', 'domain', 'suite_task'), [
    ('Cheetah-Run-v0', 'cheetah', 'run'),
    ('Walker-Walk-v0', 'walker', 'walk'),
    ('Finger-Spin-v0', 'finger', 'spin'),
])
def test_default_context_matches_the_dm_control_suite(
    build: Build, name: str, domain: str, suite_task: str
) -> None:
    """From the same state and actions, observations and rewards equal dm_control's."""
    from dm_control import suite

    task = build(name)
    state = task.reset(seed=0).state
    env = suite.load(domain, suite_task, task_kwargs={'random': 0})
    env.reset()
    with env.physics.reset_context():
        env.physics.data.qpos[:] = task.data.qpos
        env.physics.data.qvel[:] = task.data.qvel

    def flat(observation: Mapping[str, np.ndarray]) -> np.ndarray:
        return np.concatenate([np.ravel(v) for v in observation.values()])

    np.testing.assert_allclose(state, flat(env.task.get_observation(env.physics)), atol=1e-12)
    for action in np.random.default_rng(2).uniform(-1, 1, (30, task.action_dim)):
        result = task.step(action)
        reward = 0.0
        for _ in range(task.action_repeat):
            step = env.step(action)
            reward += step.reward
        np.testing.assert_allclose(result.state, flat(step.observation), atol=1e-9)
        assert result.reward == pytest.approx(reward, abs=1e-9)
    assert task.sim_time == pytest.approx(env.physics.data.time)


def test_finger_touch_observation_matches_the_suite_in_contact(build: Build) -> None:
    """While the tip presses the spinner, the touch readings equal dm_control's after a step."""
    from dm_control import suite

    task = build('Finger-Spin-v0')
    task.reset(seed=0)
    env = suite.load('finger', 'spin', task_kwargs={'random': 0})
    env.reset()
    with env.physics.reset_context():
        env.physics.data.qpos[:] = task.data.qpos
        env.physics.data.qvel[:] = task.data.qvel
    ours, theirs = [], []
    for action in np.random.default_rng(2).uniform(-1, 1, (30, task.action_dim)):
        ours.append(task.step(action).state[-2:])
        for _ in range(task.action_repeat):
            step = env.step(action)
        theirs.append(step.observation['touch'])
    assert np.max(theirs) > 1.0  # the episode really has contact
    np.testing.assert_allclose(ours, theirs, atol=1e-9)


def test_returning_to_a_context_reuses_the_compiled_model(build: Build) -> None:
    """The LRU cache compiles each geometry once while it stays cached."""
    task = build('Walker-Walk-v1')
    task.reset(seed=0)
    before = task.cache.compiles
    for value in (0.12, 0.1, 0.12, 0.1):
        task.set_context({'foot_length': value})
    assert task.cache.compiles == before + 1


def test_reward_only_context_never_recompiles(build: Build) -> None:
    """Cheetah-Run-v1 keeps its one model whatever the target velocity."""
    task = build('Cheetah-Run-v1')
    model = task.model
    for value in (0.0, 3.0, 4.0):
        task.set_context({'target_velocity': value})
    assert task.model is model and task.cache.compiles == 1


def test_episode_ends_after_episode_length_and_needs_a_reset(build: Build) -> None:
    """Exactly the episode_length-th step is last; stepping past it is an error."""
    task = build('Cheetah-Run-v1')
    assert task.reset(seed=0).first
    results = [task.step(np.zeros(task.action_dim)) for _ in range(task.episode_length)]
    assert [r.last for r in results] == [False] * (task.episode_length - 1) + [True]
    with pytest.raises(RuntimeError, match='reset'):
        task.step(np.zeros(task.action_dim))


@pytest.mark.parametrize(('context', 'fragment'), [
    ({'torso_len': 0.5}, 'unknown context parameter'),
    ({'torso_length': 9.0}, 'outside'),
    ({'torso_length': float('nan')}, 'outside'),
])
def test_bad_context_is_rejected_with_the_reason(
    build: Build, context: dict[str, float], fragment: str
) -> None:
    """Unknown names, out-of-range and non-finite values raise ValueError naming the problem."""
    task = build('Cheetah-Run-v0')
    with pytest.raises(ValueError, match=fragment):
        task.set_context(context)
    assert task.context == {'torso_length': 0.5}


def test_unknown_task_name_lists_the_valid_names() -> None:
    """make_task refuses an unknown name and lists the registered ones."""
    with pytest.raises(ValueError, match='Cheetah-Run-v0'):
        make_task('Cheetah-Fly-v0')
    assert set(DMC_TASKS) < set(TASK_NAMES)


@pytest.mark.parametrize('split', SPLITS)
@pytest.mark.parametrize('name', DMC_TASKS)
def test_every_preset_value_builds_a_valid_model(name: str, split: str) -> None:
    """Each value of the paper's tables compiles, resets and steps to a finite state."""
    for context in load_preset(name, split):
        task = make_task(name, seed=0, context=context)
        task.reset()
        result = task.step(np.zeros(task.action_dim))
        assert np.isfinite(result.state).all() and np.isfinite(result.reward), context
        assert result.context == context


@pytest.mark.slow
def test_render_is_an_84x84_rgb_uint8_frame(build: Build) -> None:
    """The default frame is what the pixel encoder expects: 84x84x3 uint8, not blank."""
    task = build('Walker-Walk-v0')
    task.reset(seed=0)
    frame = task.render()
    assert frame.shape == (84, 84, 3) and frame.dtype == np.uint8
    assert frame.std() > 1.0
