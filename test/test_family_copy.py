"""A copied built-in family file is the user's own family, and training deploys with a read-out.

Issue 52 items 3 and 6: a copy of params/tasks/Cheetah-Bias-v0.yaml, renamed, is accepted
wherever a task file is (collect, train, eval, the launch plan), and `zeus train`'s final.pt
carries the context read-out and novelty monitor that `zeus export` fits.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from sim_bridge.families import builtin_family_file, family
from sim_bridge.registry import make_task
from sim_bridge.task_files import load_task_file

from tiny_config import TINY, write_config


def _copy(tmp_path: Path, name: str = 'my_family.yaml', *, rename: bool = True,
          replace: tuple[str, str] = ('', '')) -> Path:
    """The built-in Cheetah-Bias-v0 file copied to `name` (its task renamed to My-Bias-v0)."""
    text = builtin_family_file('Cheetah-Bias-v0').read_text()
    if rename:
        text = text.replace('task: Cheetah-Bias-v0', 'task: My-Bias-v0\nbuiltin: Cheetah-Bias-v0')
    path = tmp_path / name
    path.write_text(text.replace(*replace) if replace[0] else text)
    return path


def test_a_verbatim_and_a_renamed_copy_are_families(tmp_path: Path) -> None:
    """Both load; the renamed one runs under its own name with the file's presets."""
    verbatim = load_task_file(_copy(tmp_path, 'copy.yaml', rename=False))
    assert verbatim.name == 'Cheetah-Bias-v0'
    mine = _copy(tmp_path, replace=('train: [-0.3, -0.25, -0.2, -0.15, 0.15, 0.2, 0.25, 0.3]',
                                    'train: [-0.3, 0.3]'))
    task = make_task(str(mine), seed=0, context={'motor_bias': 0.3})
    try:
        assert task.name == 'My-Bias-v0' and task.context == {'motor_bias': 0.3}
        assert task.reset().state.shape == (17,)
    finally:
        task.close()
    assert family(str(mine)).preset('train') == [{'motor_bias': -0.3}, {'motor_bias': 0.3}]


@pytest.mark.parametrize(('replace', 'message'), [
    (('builtin: Cheetah-Bias-v0', 'builtin: Cheetah-Bias-v9'), 'not a built-in family'),
    (('range: [-1.0, 1.0]', 'range: [-2.0, 1.0]'), 'wider than Cheetah-Bias-v0 accepts'),
    (('motor_bias: {', 'motor_gain: {'), 'simulates motor_bias only'),
])
def test_a_copy_that_the_simulator_cannot_run_is_refused(tmp_path: Path,
                                                         replace: tuple[str, str],
                                                         message: str) -> None:
    """A copy names what is wrong in one line: the built-in, the range, the parameter."""
    with pytest.raises(ValueError, match=message):
        load_task_file(_copy(tmp_path, replace=replace))


def test_collect_train_eval_and_launch_a_renamed_copy(tmp_path: Path) -> None:
    """The journey on the user's file; final.pt carries the read-out as an export does."""
    from zeus_ros.cli import collect, evaluate, train
    from zeus_ros.learning.checkpoint import load_checkpoint
    from zeus_ros.system.launch_defaults import plan

    mine = str(_copy(tmp_path))
    bags, run = tmp_path / 'bags', tmp_path / 'run'
    assert collect.main(['--task', mine, '--steps', '240', '--schedule',
                         'switch:values=train,every=20', '--out', str(bags),
                         '--no-progress']) == 0
    config = write_config(tmp_path / 'tiny.yaml', TINY | {'num_updates': 20})
    assert train.main(['--bags', str(bags), '--task', mine, '--config', str(config), '--out',
                       str(run), '--no-eval', '--no-progress', '--readout-steps', '240',
                       '--threads', '1']) == 0
    loaded = load_checkpoint(run / 'final.pt')
    assert loaded.spec.task == 'My-Bias-v0'
    readout = loaded.extra['context_readout']
    assert readout['names'] == ['motor_bias'] and 'train contexts' in readout['fitted_on']
    assert 'context_novelty' in loaded.extra
    assert evaluate.main(['--checkpoint', str(run / 'final.pt'), '--task', mine,
                          '--episodes', '1', '--probe-steps', '0', '--out',
                          str(tmp_path / 'eval'), '--no-progress']) == 0
    launch = plan(task=mine, checkpoint=str(run / 'final.pt'))
    bridge = next(node for node in launch.nodes if node.name == 'sim_bridge')
    assert bridge.parameters['task'] == mine


def test_train_without_readout_steps_leaves_final_without_one(tmp_path: Path) -> None:
    """--readout-steps 0: the old behaviour, nothing fitted (the export still can)."""
    from zeus_ros.cli import collect, train
    from zeus_ros.learning.checkpoint import load_checkpoint

    bags, run = tmp_path / 'bags', tmp_path / 'run'
    assert collect.main(['--task', 'Cheetah-Bias-v0', '--steps', '80', '--out', str(bags),
                         '--no-progress']) == 0
    config = write_config(tmp_path / 'tiny.yaml', TINY | {'num_updates': 2})
    assert train.main(['--bags', str(bags), '--config', str(config), '--out', str(run),
                       '--no-eval', '--no-progress', '--readout-steps', '0']) == 0
    assert 'context_readout' not in load_checkpoint(run / 'final.pt').extra
