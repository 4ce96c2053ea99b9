"""A task family is one declaration, and the zoo is what the package installs and deploys."""

from __future__ import annotations

import hashlib
from pathlib import Path
import re

import pytest
import yaml

from sim_bridge.families import family
from sim_bridge.registry import TASK_NAMES, task_class

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize('task', TASK_NAMES)
def test_every_built_in_family_reads_from_its_file(task: str) -> None:
    """The class's context parameters are the file's; every preset value lies in its range."""
    declared = family(task)
    assert declared.source == ROOT / 'params' / 'tasks' / f'{task}.yaml'
    assert task_class(task).specs == declared.specs
    assert set(declared.presets) == {'train', 'interpolation', 'extrapolation'}
    for values in declared.presets.values():
        for value in values:
            for spec in declared.specs:
                assert spec.low <= value[spec.name] <= spec.high
    assert set(declared.training) == {'alpha_psi', 'adam_beta1'}


def test_no_task_name_table_is_left_in_the_learning_core() -> None:
    """Per-task knowledge lives in params/tasks/: the learning package names no task family."""
    names = '|'.join(re.escape(name) for name in TASK_NAMES)
    for path in (ROOT / 'zeus_ros' / 'learning').glob('*.py'):
        code = '\n'.join(line for line in path.read_text().splitlines()
                         if not line.strip().startswith('#'))
        strings = re.findall(rf"""['"]({names})['"]""", code)
        assert not strings, f'{path.name} names {strings}'


def test_a_broken_family_file_is_named_with_the_bad_entry(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """A preset outside the parameter's range names the file, the split and the range."""
    from sim_bridge import families, family_schema

    params = tmp_path / 'params'
    (params / 'tasks').mkdir(parents=True)
    data = yaml.safe_load((ROOT / 'params' / 'tasks' / 'Cheetah-Bias-v0.yaml').read_text())
    data['presets']['extrapolation'] = [1.5]
    (params / 'tasks' / 'Cheetah-Bias-v0.yaml').write_text(yaml.safe_dump(data))
    monkeypatch.setattr(family_schema, 'find_params_dir', lambda: params)
    families._builtin_family.cache_clear()
    try:
        with pytest.raises(ValueError, match=r'Cheetah-Bias-v0.yaml: presets: extrapolation: '
                           r'motor_bias 1.5 outside its range \[-1.0, 1.0\]'):
            families.family('Cheetah-Bias-v0')
    finally:
        families._builtin_family.cache_clear()


def test_the_zoo_has_every_declared_checkpoint_with_its_card_in_the_index() -> None:
    """Each family's declared checkpoint and its references exist, with a card and a sha256."""
    manifest = yaml.safe_load((ROOT / 'checkpoints' / 'zoo.yaml').read_text())['families']
    index = (ROOT / 'checkpoints' / 'README.md').read_text()
    for task in TASK_NAMES:
        declared = family(task).checkpoint
        assert (declared is not None) == (task in manifest), task
    for task, entry in manifest.items():
        folder = ROOT / 'checkpoints' / task.lower().replace('-', '_')
        assert family(task).checkpoint == f'{folder.name}/zeus.pt'
        for method in entry['methods']:
            path = folder / f'{method}.pt'
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            assert digest in path.with_suffix('.md').read_text(), path
            assert f'`{digest[:12]}`' in index, path


def test_the_default_deployment_reads_its_context() -> None:
    """params/zeus.yaml deploys a checkpoint whose actions move with psi (card: >= 0.05)."""
    params = yaml.safe_load((ROOT / 'params' / 'zeus.yaml').read_text())
    checkpoint = params['/**/policy']['ros__parameters']['checkpoint']
    assert checkpoint == params['/**/context_estimator']['ros__parameters']['checkpoint']
    card = (ROOT / 'params' / checkpoint).with_suffix('.md')
    card = card if card.is_file() else (ROOT / checkpoint).with_suffix('.md')
    sensitivity = float(re.search(r'Context sensitivity .*\*\*([0-9.]+)\*\*',
                                  card.read_text()).group(1))
    assert sensitivity >= 0.05
    voa = re.search(r'\| extrapolation \| [^|]+ \| (-?[0-9.]+) ± ([0-9.]+) \|', card.read_text())
    assert float(voa.group(1)) > 2 * float(voa.group(2))


def test_setup_installs_the_zoo_and_nothing_of_the_archive() -> None:
    """share/zeus_ros/checkpoints gets the zoo folders, the index and the manifest: few, small."""
    import ast

    source = (ROOT / 'setup.py').read_text()
    tree = ast.parse(source)
    namespace: dict = {'__file__': str(ROOT / 'setup.py')}
    functions = [node for node in tree.body if isinstance(node, ast.FunctionDef | ast.Import |
                                                             ast.ImportFrom | ast.Assign)]
    import os

    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        exec(compile(ast.Module(body=functions, type_ignores=[]), 'setup.py', 'exec'), namespace)
        entries = namespace['zoo_files']()
    finally:
        os.chdir(cwd)
    files = [Path(ROOT / f) for _target, paths in entries for f in paths]
    assert len(files) <= 40
    assert sum(f.stat().st_size for f in files) <= 30e6
    assert not any('issue10' in str(f) or 'comparison' in str(f) for f in files)
    assert any(f.name == 'zeus.pt' and f.parent.name == 'cheetah_bias_v0' for f in files)


def test_launch_with_a_task_runs_its_schedule_and_zoo_checkpoint() -> None:
    """`zeus launch --task` / task:= set sim_bridge's family and schedule, and the pair."""
    from zeus_ros.system import launch_defaults

    plan = launch_defaults.plan_from_arguments({'task': 'Cheetah-Motor-v0'})
    nodes = {node.name: node.parameters for node in plan.nodes}
    assert nodes['sim_bridge']['task'] == 'Cheetah-Motor-v0'
    every, values = family('Cheetah-Motor-v0').demo_schedule()
    assert nodes['sim_bridge']['schedule.every'] == every == 20
    assert nodes['sim_bridge']['schedule.values'] == values
    assert set(values) == {v['motor_gain'] for split in ('train', 'extrapolation')
                           for v in family('Cheetah-Motor-v0').preset(split)}
    pair = {nodes[n]['checkpoint'] for n in ('context_estimator', 'policy')}
    assert pair == {str(ROOT / 'checkpoints' / 'cheetah_motor_v0' / 'zeus.pt')}
    with pytest.raises(ValueError, match='Walker-Walk-v0 has no zoo checkpoint'):
        launch_defaults.plan(task='Walker-Walk-v0')
    given = launch_defaults.plan(task='Walker-Walk-v0', checkpoint=str(
        ROOT / 'checkpoints' / 'cheetah_bias_v0' / 'zeus.pt'))
    assert {n.name for n in given.nodes} >= {'sim_bridge', 'policy'}


def test_launch_with_pixels_renders_frames_for_the_zoo_pixel_checkpoint() -> None:
    """`zeus launch --obs pixels` / obs:=pixels: sim_bridge's frames and the pixel pair."""
    from zeus_ros.system import launch_defaults

    plan = launch_defaults.plan_from_arguments({'obs': 'pixels'})
    nodes = {node.name: node.parameters for node in plan.nodes}
    assert nodes['sim_bridge']['pixels'] is True
    pair = {nodes[n]['checkpoint'] for n in ('context_estimator', 'policy')}
    assert pair == {str(ROOT / 'checkpoints' / 'cheetah_bias_v0' / 'pixels_student.pt')}
    state = launch_defaults.plan(obs='state')
    assert {n.name: n.parameters for n in state.nodes}['sim_bridge']['pixels'] is False
    assert 'pixels' not in {n.name: n.parameters for n in launch_defaults.plan().nodes}[
        'sim_bridge']  # '': the params file decides
    with pytest.raises(ValueError, match=r'Cheetah-Run-v1 has no pixel checkpoint.*'
                       r'families with one: Cheetah-Motor-v0, Cheetah-Bias-v0'):
        launch_defaults.plan(task='Cheetah-Run-v1', obs='pixels')
    motor = launch_defaults.plan(task='Cheetah-Motor-v0', obs='pixels')
    assert {n.parameters['checkpoint'] for n in motor.nodes if n.name in (
        'context_estimator', 'policy')} == {
        str(ROOT / 'checkpoints' / 'cheetah_motor_v0' / 'pixels_student.pt')}
    with pytest.raises(ValueError, match="obs 'camera'"):
        launch_defaults.plan(obs='camera')


def test_every_params_file_the_docs_name_exists() -> None:
    """A config, task or params file named in the README or docs/ is one a user can open."""
    named = set()
    for doc in [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]:
        named |= {(doc.name, m) for m in re.findall(r'params/[\w/.-]+\.(?:yaml|xml)',
                                                     doc.read_text())}
    missing = sorted((doc, path) for doc, path in named if not (ROOT / path).is_file())
    assert not missing, missing


def test_every_installed_checkpoint_is_in_the_index() -> None:
    """Each .pt of the installed zoo folders has its sha256 in checkpoints/README.md."""
    manifest = yaml.safe_load((ROOT / 'checkpoints' / 'zoo.yaml').read_text())['families']
    index = (ROOT / 'checkpoints' / 'README.md').read_text()
    for task in manifest:
        for path in (ROOT / 'checkpoints' / task.lower().replace('-', '_')).glob('*.pt'):
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            assert f'`{digest[:12]}`' in index, path
            assert path.with_suffix('.md').is_file(), path
