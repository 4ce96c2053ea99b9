"""`zeus <command> --help` and a wrong path answer before torch, MuJoCo or ROS load (issue 52).

Under load the heavy imports took 30-113 s before a command said anything; each command now
parses its arguments and checks its paths first. Both checks run every command in one fresh
interpreter and look at sys.modules after each, so the first command to import a heavy module
is the one named.
"""

from __future__ import annotations

import json
from pathlib import Path
import subprocess
import sys

import pytest

from zeus_ros.cli import SUBCOMMANDS

HEAVY = ('torch', 'mujoco', 'dm_control', 'rclpy')
"""What a --help or an argument error must not import."""

_PROBE = r"""
import contextlib, io, json, sys
from zeus_ros.cli import main
heavy = HEAVY
results = []
for argv in json.loads(sys.argv[1]):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as stop:
            code = stop.code
    results.append({'argv': argv, 'code': code, 'out': out.getvalue(), 'err': err.getvalue(),
                    'heavy': [name for name in heavy if name in sys.modules]})
print(json.dumps(results))
""".replace('HEAVY', repr(HEAVY))


def _probe(argvs: list[list[str]], cwd: Path) -> list[dict]:
    """Run `zeus ARGV` for each ARGV in one fresh interpreter; what each said and imported."""
    done = subprocess.run([sys.executable, '-c', _PROBE, json.dumps(argvs)], cwd=cwd,
                          capture_output=True, text=True, timeout=600, check=True)
    return json.loads(done.stdout)


def test_every_help_answers_without_heavy_imports(tmp_path: Path) -> None:
    """`zeus <command> --help` for every command: exit 0, usage printed, no torch/MuJoCo/ROS."""
    for result in _probe([[name, '--help'] for name in SUBCOMMANDS], tmp_path):
        name = result['argv'][0]
        assert result['code'] in (0, None), (name, result['err'])
        assert 'usage:' in result['out'], name
        assert result['heavy'] == [], f'zeus {name} --help imported {result["heavy"]}'


MISSING = [
    ['train', '--bags', '/nonexistent', '--config', 'params/train/state_cpu.yaml', '--out', 'x'],
    ['train', '--bags', '.', '--config', 'params/train/state_cpux.yaml', '--out', 'x'],
    ['train', '--bags', '.', '--config', 'params/train/state_cpu.yaml', '--out', 'x',
     '--task-file', 'nope.yaml'],
    ['eval', '--checkpoint', 'nope.pt'],
    ['export', '--checkpoint', 'nope.pt', '--out', 'x.pt'],
    ['distill', '--task', 'Cheetah-Bias-v0', '--teacher', 'nope.pt', '--out', 'x'],
    ['loop', '--task', 'Cheetah-Bias-v0', '--config', 'nope.yaml', '--out', 'x'],
    ['sweep', '--tasks', 'Cheetah-Bias-v0', '--methods', 'zeus', '--config', 'nope.yaml',
     '--out', 'x'],
    ['collect', '--task', 'Cheetah-Bias-v0', '--steps', '5', '--out', 'x', '--checkpoint',
     'nope.pt'],
    ['adaptation', '--checkpoint', 'nope.pt'],
    ['ingest', '--bags', '/nonexistent'],
    ['report', '--folder', '/nonexistent'],
]
"""A mistyped file or folder for every command that reads one (the rest of the line is good)."""


def test_a_missing_path_is_one_line_exit_2_before_heavy_imports(tmp_path: Path) -> None:
    """Exit 2, one stderr line naming the flag and the path, nothing heavy imported, no output."""
    for result in _probe(MISSING, tmp_path):
        argv = result['argv']
        name, path = argv[0], next(a for a in argv if 'nope' in a or 'nonexistent' in a
                                   or 'cpux' in a)
        flag = argv[argv.index(path) - 1]
        err = result['err'].strip()
        assert result['code'] == 2, (argv, err)
        assert len(err.splitlines()) == 1, (argv, err)
        assert err.startswith(f'zeus {name}: ') and flag in err and path in err, (argv, err)
        assert result['heavy'] == [], f'zeus {" ".join(argv)} imported {result["heavy"]}'
    assert not (tmp_path / 'x').exists()


def test_the_issue_command_fails_at_once(tmp_path: Path) -> None:
    """The report's `zeus train --bags /nonexistent --config ...`: one line, exit 2, no torch."""
    [result] = _probe([['train', '--bags', '/nonexistent', '--config',
                        'params/train/state_cpu.yaml']], tmp_path)
    assert result['code'] == 2 and len(result['err'].strip().splitlines()) == 1, result
    assert 'torch' not in result['heavy']


def test_the_light_copies_match_what_they_stand_for() -> None:
    """The torch-free method names and adaptation seed the --help shows are the real ones."""
    from zeus_ros.cli.adaptation import EVAL_SEED
    from zeus_ros.learning.method_names import METHOD_NAMES
    from zeus_ros.learning.methods import METHODS
    from zeus_ros.offline.evaluation import adaptation

    assert METHOD_NAMES == METHODS
    assert adaptation.EVAL_SEED == EVAL_SEED


@pytest.mark.parametrize('command', ['train', 'loop'])
def test_a_config_from_the_package_share_still_passes_the_check(
        command: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--config params/train/state_cpu.yaml from another folder is found in the share."""
    import importlib

    monkeypatch.chdir(tmp_path)
    parser = importlib.import_module(SUBCOMMANDS[command][0])._build_parser()
    argv = ['--config', 'params/train/state_cpu.yaml', '--out', 'x',
            *(['--bags', '.'] if command == 'train' else ['--task', 'Cheetah-Bias-v0'])]
    assert parser.parse_args(argv).config == Path('params/train/state_cpu.yaml')


def test_a_mistyped_config_or_task_file_is_answered_with_the_nearest(tmp_path: Path) -> None:
    """A near-miss config or task file names the real one, still one line and nothing heavy."""
    results = _probe([
        ['train', '--bags', '.', '--config', 'params/train/state_cpux.yaml', '--out', 'x'],
        ['train', '--bags', '.', '--config', 'state_cpu.yml', '--out', 'x'],
        ['eval', '--task', 'params/tasks/Cheetah-Bais-v0.yaml', '--checkpoint', 'x.pt'],
        ['eval', '--task', 'Cheetah-Bais-v0', '--checkpoint', 'x.pt'],
    ], tmp_path)
    wanted = ["did you mean 'params/train/state_cpu.yaml'?",
              "did you mean 'params/train/state_cpu.yaml'?",
              "did you mean 'params/tasks/Cheetah-Bias-v0.yaml'?",
              "did you mean 'Cheetah-Bias-v0'?"]
    for result, want in zip(results, wanted, strict=True):
        err = result['err'].strip()
        assert result['code'] == 2 and len(err.splitlines()) == 1, (result['argv'], err)
        assert want in err, (result['argv'], err)
        assert result['heavy'] == [], (result['argv'], result['heavy'])


def test_no_suggestion_for_a_path_with_nothing_near(tmp_path: Path) -> None:
    """An unrelated name gets no guess: a wrong 'did you mean' misleads more than none."""
    [result] = _probe([['eval', '--checkpoint', 'nope.pt']], tmp_path)
    assert result['code'] == 2 and 'did you mean' not in result['err'], result['err']
