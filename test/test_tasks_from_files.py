"""Tasks declared in YAML: a built-in family re-expressed, the shipped example end to end."""

from __future__ import annotations

from pathlib import Path
import textwrap
import warnings

import numpy as np
import pytest
import yaml

from sim_bridge.families import load_preset
from sim_bridge.registry import make_task

from ros_harness import REPO

TASKS = REPO / 'params' / 'tasks'
WALKER = TASKS / 'walker_friction.yaml'
PAYLOAD = TASKS / 'payload_point_mass.yaml'


@pytest.mark.slow
def test_walker_friction_as_a_task_file_matches_the_class_step_for_step() -> None:
    """Same seed, same actions, a mid-episode friction switch: identical states and rewards."""
    from sim_bridge.walker import WalkerFrictionTask

    from_file = make_task(str(WALKER), seed=7, context={'friction': 1.2})
    built_in = WalkerFrictionTask(seed=7, context={'friction': 1.2})
    assert from_file.state_dim == built_in.state_dim == 24
    for low, high in zip(from_file.action_bounds, built_in.action_bounds, strict=True):
        np.testing.assert_array_equal(low, high)
    a, b = from_file.reset(), built_in.reset()
    np.testing.assert_array_equal(a.state, b.state)
    rng = np.random.default_rng(0)
    for step in range(80):
        if step == 40:  # unannounced, mid-episode: the state carries over in both
            from_file.set_context({'friction': 0.3})
            built_in.set_context({'friction': 0.3})
        action = rng.uniform(-1, 1, 6)
        a, b = from_file.step(action), built_in.step(action)
        np.testing.assert_array_equal(a.state, b.state)
        assert a.reward == b.reward
    assert from_file.model.geom('floor').friction[0] == 0.3
    assert from_file.model.geom('floor').priority == 1
    for split in ('train', 'interpolation', 'extrapolation'):  # the paper's values, in the file
        assert load_preset(from_file.name, split) == load_preset('Walker-Walk-v0', split)


@pytest.mark.slow
def test_the_example_task_collects_trains_and_evaluates(tmp_path: Path) -> None:
    """`zeus collect` / `train` / `eval` with --task-file on the shipped payload point mass."""
    from zeus_ros.cli.collect import main as collect
    from zeus_ros.cli.evaluate import main as evaluate
    from zeus_ros.cli.train import main as train
    from zeus_ros.offline.data.ingest import ingest_bags

    bags = tmp_path / 'bags'
    assert collect(['--task-file', str(PAYLOAD), '--steps', '300', '--schedule',
                    'switch:train:every=50', '--out', str(bags), '--no-progress']) == 0
    data = ingest_bags([bags])
    assert data.task == 'PointMass-Payload-v0' and data.context_names == ('payload_mass',)
    masses = np.unique(np.concatenate([e.context[:, 0] for e in data.episodes]))
    assert set(masses.round(6)) <= {0.05, 0.1, 0.3, 0.6, 1.0} and len(masses) >= 3
    config = tmp_path / 'tiny.yaml'
    config.write_text(yaml.safe_dump({
        'method': 'zeus', 'k': 3, 'context_dim': 4, 'transition_dim': 8,
        'context_hidden_dim': 16, 'feature_dim': 8, 'encoder_hidden_dim': 32,
        'hidden_dim': 32, 'model_hidden_dim': 32, 'batch_size': 16, 'num_updates': 20,
        'eval_interval': 20, 'eval_episodes': 1, 'checkpoint_interval': 20,
        'log_interval': 10, 'device': 'cpu', 'alpha_psi': 1.0, 'adam_beta1': 0.9}))
    run = tmp_path / 'run'
    assert train(['--bags', str(bags), '--config', str(config), '--out', str(run),
                  '--task-file', str(PAYLOAD), '--no-progress', '--threads', '1']) == 0
    assert (run / 'eval.csv').is_file()  # periodic evaluation ran on the declared task
    out = tmp_path / 'eval'
    assert evaluate(['--checkpoint', str(run / 'final.pt'), '--task-file', str(PAYLOAD),
                     '--split', 'extrapolation', '--episodes', '1', '--probe-steps', '0',
                     '--out', str(out), '--no-progress']) == 0
    assert any(out.rglob('*.csv'))


def _model(tmp_path: Path) -> Path:
    xml = tmp_path / 'm.xml'
    xml.write_text(textwrap.dedent("""\
        <mujoco>
          <option timestep="0.01"/>
          <worldbody>
            <geom name="floor" type="plane" size="1 1 0.1"/>
            <body name="arm" pos="0 0 0.5">
              <joint name="hinge" type="hinge" axis="0 1 0"/>
              <geom name="link" type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" density="1000"/>
              <body name="tip" pos="0.3 0 0"><geom name="tip" type="sphere" size="0.03"/></body>
            </body>
          </worldbody>
          <actuator>
            <motor name="m1" joint="hinge" gear="2"/><motor name="m2" joint="hinge" gear="4"/>
          </actuator>
          <sensor><jointpos name="angle" joint="hinge"/></sensor>
        </mujoco>"""))
    return xml


def _task_file(tmp_path: Path, context: dict, **extra: object) -> Path:
    _model(tmp_path)
    path = tmp_path / 'task.yaml'
    path.write_text(yaml.safe_dump({
        'name': 'Arm-Test-v0', 'model': 'm.xml', 'episode_length': 20,
        'observation': ['joint:hinge.qpos', 'joint:hinge.qvel', 'sensor:angle.data'],
        'reward': 'velocity:hinge', 'context': context, **extra}))
    return path


def test_context_paths_set_scale_follow_and_keep_the_state(tmp_path: Path) -> None:
    """option.gravity scaled, every actuator's gear scaled, mass follows a geometry change."""
    path = _task_file(tmp_path, {
        'gravity': {'paths': ['option.gravity[2]'], 'mapping': 'scale', 'default': 1.0,
                    'range': [0.1, 3.0]},
        'strength': {'paths': ['actuator:*.gear[0]'], 'mapping': 'scale', 'default': 1.0,
                     'range': [0.1, 3.0]},
        'radius': {'paths': ['geom:link.size[0]', {'path': 'body:tip.pos[2]', 'factor': 2.0,
                                                  'offset': 0.01}],
                   'default': 0.02, 'range': [0.01, 0.1]}})
    task = make_task(str(path), seed=0)
    light = task.model.body('arm').mass[0]
    task.reset()
    for _ in range(5):
        task.step(np.ones(2))
    qpos, qvel = task.data.qpos.copy(), task.data.qvel.copy()
    task.set_context({'gravity': 2.0, 'strength': 0.5, 'radius': 0.04})
    np.testing.assert_array_equal(task.data.qpos, qpos)  # the state carries over
    np.testing.assert_array_equal(task.data.qvel, qvel)
    assert task.model.opt.gravity[2] == pytest.approx(-9.81 * 2.0)
    assert task.model.actuator_gear[:, 0].tolist() == [1.0, 2.0]
    assert task.model.body('tip').pos[2] == pytest.approx(0.09)
    # Constant density: a capsule of twice the radius is about four times as heavy.
    assert 3.5 < task.model.body('arm').mass[0] / light < 4.5
    assert task.step(np.ones(2)).state.shape == (3,)


@pytest.mark.parametrize(('context', 'message'), [
    ({'c': {'paths': ['geom:lnk.size[0]'], 'default': 0.02}},
     "no geom named 'lnk'; the model's geoms: floor, link, tip"),
    ({'c': {'paths': ['geom:link.sise[0]'], 'default': 0.02}}, "a geom has no attribute 'sise'"),
    ({'c': {'paths': ['geom:link.size[7]'], 'default': 0.02}}, 'index 7 out of range'),
    ({'c': {'paths': ['body:arm.mass'], 'default': 1.0}}, 'takes its mass from its geoms'),
    ({'c': {'paths': ['wheel.radius'], 'default': 1.0}}, 'is not a model path'),
    ({'c': {'paths': ['geom:link.size[0]'], 'mapping': 'double', 'default': 1.0}},
     "mapping 'double'"),
])
def test_a_bad_path_names_itself_and_the_models_elements(tmp_path: Path, context: dict,
                                                         message: str) -> None:
    """Validation happens when the file is read, with the file's name in the message."""
    with pytest.raises(ValueError, match=r'task file .*task\.yaml') as error:
        make_task(str(_task_file(tmp_path, context)))
    assert message in str(error.value)


def test_a_bad_observation_or_reward_is_found_when_the_file_is_read(tmp_path: Path) -> None:
    """Unknown joint in the observation or the reward, unknown camera."""
    path = _task_file(tmp_path, {}, observation=['joint:elbow.qpos'])
    with pytest.raises(ValueError, match="no joint named 'elbow'; the model's joints: hinge"):
        make_task(str(path))
    path = _task_file(tmp_path, {}, reward='velocity:elbow')
    with pytest.raises(ValueError, match="no joint 'elbow'"):
        make_task(str(path))
    path = _task_file(tmp_path, {}, camera='side')
    with pytest.raises(ValueError, match="no camera named 'side'; the model's cameras: none"):
        make_task(str(path))


@pytest.mark.ros
def test_sim_bridge_and_the_random_policy_run_a_task_file(tmp_path: Path) -> None:
    """The same file for the node: steps carry the declared name and context."""
    from zeus_msgs.msg import ContextTruth, StepFeedback

    from zeus_ros.nodes.topics import step_qos

    from live_fixtures import node
    from ros_harness import ProcessGroup, driver_node, fresh_domain_id, require_ros, spin_until

    require_ros()
    group = ProcessGroup(domain_id=fresh_domain_id())
    seen: dict[int, str] = {}
    try:
        with driver_node(group.domain_id) as driver:
            truths: dict[int, float] = {}
            # A passive observer does not pace the lockstep loop: under load it falls behind,
            # and a keep-last-10 reader would drop steps (seen: 5-6 in a row), so it keeps 1000.
            deep = step_qos(1000)
            readers = [
                driver.create_subscription(StepFeedback, 'zeus/step', lambda m: seen.__setitem__(
                    m.step, m.task), deep),
                driver.create_subscription(ContextTruth, 'zeus/context_truth', lambda m: truths
                                           .__setitem__(m.step, m.values[0]), deep)]
            bridge = group.start('sim_bridge_task_file', node(
                'sim_bridge', f'task:={PAYLOAD}', 'max_steps:=30', 'min_observers:=2',
                'schedule.kind:=switch', 'schedule.values:=train', 'schedule.every:=10'))
            # The policy (the loop's last peer) only once this bystander's readers matched the
            # bridge on their side too: sim_bridge sees only its writers' side of each match.
            assert spin_until(driver, lambda: all(r.get_publisher_count() for r in readers), 90)
            group.start('policy_task_file', node('policy', f'task:={PAYLOAD}'))
            assert spin_until(driver, lambda: len(seen) > 30, 90), (
                f'steps never seen: {sorted(set(range(31)) - set(seen))}',
                group.log_text('sim_bridge_task_file')[-2000:])
        assert bridge.wait(timeout=30) == 0
    finally:
        group.stop_all()
    assert set(seen.values()) == {'PointMass-Payload-v0'}
    assert [truths[s] for s in (0, 10, 20)] == [0.05, 0.1, 0.3]  # the file's train presets


# --- Issue 52: no settotalmass warning from the suite's cheetah ----------------------------------

_SUITE_CHEETAH_FILE = {
    'name': 'Cheetah-Gear-File-v0', 'model': 'suite:cheetah.xml', 'episode_length': 10,
    'observation': ['joint:*.qpos', 'joint:*.qvel'], 'reward': 'velocity:rootx',
    'context': {
        'gain': {'paths': ['actuator:*.gear[0]'], 'mapping': 'scale', 'default': 1.0,
                 'range': [0.1, 2.0]},
        'torso_radius': {'paths': ['geom:torso.size[0]'], 'default': 0.046,
                         'range': [0.02, 0.1]}}}


def _run_briefly(task_name: str, context: dict[str, float]) -> None:
    """Build, recompile for another context (a geometry change included), render-free steps."""
    task = make_task(task_name, seed=0)
    task.reset()
    task.set_context(context)
    task.step(np.zeros(6))
    task.close()


@pytest.mark.parametrize('which', ['Cheetah-Bias-v0', 'Cheetah-Motor-v0', 'suite file'])
def test_cheetah_tasks_compile_without_the_settotalmass_warning(
        tmp_path: Path, capfd: pytest.CaptureFixture[str], which: str) -> None:
    """No MuJoCo settotalmass deprecation, neither as a Python warning nor on stderr.

    The built-in families replace settotalmass by a density; a `suite:cheetah.xml` task file
    compiles dm_control's model as is, its warning silenced (sim_bridge/model_edit.py).
    """
    name, context = which, {'Cheetah-Bias-v0': {'motor_bias': 0.4},
                            'Cheetah-Motor-v0': {'motor_gain': 0.5}}.get(which, {})
    if which == 'suite file':
        path = tmp_path / 'cheetah_gear.yaml'
        path.write_text(yaml.safe_dump(_SUITE_CHEETAH_FILE))
        name, context = str(path), {'gain': 0.5, 'torso_radius': 0.08}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        _run_briefly(name, context)
    assert not [w for w in caught if 'settotalmass' in str(w.message)], \
        [str(w.message) for w in caught]
    assert 'settotalmass' not in capfd.readouterr().err


def test_a_suite_cheetah_file_keeps_the_suites_masses_and_solver_scale(tmp_path: Path) -> None:
    """Silencing, not replacing: the compiled model is dm_control's (total 14 kg, same stats)."""
    from dm_control import suite

    path = tmp_path / 'cheetah_gear.yaml'
    path.write_text(yaml.safe_dump(_SUITE_CHEETAH_FILE))
    model = make_task(str(path), seed=0).model
    reference = suite.load('cheetah', 'run', task_kwargs={'random': 0}).physics.model
    np.testing.assert_array_equal(model.body_mass, reference.body_mass)
    assert model.stat.meaninertia == reference.stat.meaninertia
    assert model.stat.meanmass == reference.stat.meanmass


def test_a_users_own_mjcf_with_settotalmass_still_warns(tmp_path: Path) -> None:
    """Only dm_control's file is silenced: in the user's own model the warning can be acted on."""
    path = _task_file(tmp_path, {})
    xml = tmp_path / 'm.xml'
    xml.write_text(xml.read_text().replace('<mujoco>', '<mujoco>\n<compiler settotalmass="3"/>'))
    with pytest.warns(UserWarning, match='settotalmass'):
        make_task(str(path))
