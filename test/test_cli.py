"""One error style for every `zeus` command, task names in --help, paths from any folder."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from sim_bridge.registry import TASK_NAMES
from zeus_ros.cli import INTERNAL, SUBCOMMANDS, usage


def _run(command: str, argv: list[str]) -> int:
    main = importlib.import_module(SUBCOMMANDS[command][0]).main
    try:
        return int(main(argv) or 0)
    except SystemExit as stop:
        return int(stop.code or 0)


BAD_VALUES = [
    ('collect', ['--task', 'cheetah-run-v0', '--steps', '5', '--out', 'x'], '--task',
     "did you mean 'Cheetah-Run-v0'"),
    ('collect', ['--task', 'Cheetah-Run-v0', '--steps', 'many', '--out', 'x'], '--steps',
     "'many' is not an integer"),
    ('collect', ['--task', 'Cheetah-Run-v0', '--steps', '5', '--out', 'x', '--storage', 'zip'],
     '--storage', "(choose from 'mcap', 'sqlite3')"),
    ('collect', ['--task', 'Cheetah-Run-v0', '--steps', '5', '--out', 'x', '--schedule',
                 'swich:train:every=10'], '--schedule', 'allowed: constant, switch'),
    ('train', ['--bags', 'b', '--config', 'c.yaml', '--out', 'o', '--method', 'zeuss'],
     '--method', "did you mean 'zeus'"),
    ('train', ['--bags', 'b', '--config', 'c.yaml', '--out', 'o', '--task', 'finger'],
     '--task', 'Finger-Spin-v0'),
    ('eval', ['--checkpoint', 'c.pt', '--split', 'extrapolate'], '--split',
     "did you mean 'extrapolation'"),
    ('loop', ['--task', 'Cheetah-Run-v0', '--config', 'c.yaml', '--out', 'o', '--method', 'x'],
     '--method', "choose from 'zeus'"),
    ('launch', ['--log-level', 'loud'], '--log-level', "choose from 'debug'"),
    ('inspect', ['--duration', 'soon'], '--duration', "'soon' is not a number"),
    ('demo', ['--task', 'Cheetah-Run-v2'], '--task', "did you mean 'Cheetah-Run-v1'"),
    ('report', ['--out', 'o'], '--folder', 'required'),
    ('recover', ['--dry-run'], '--bags', 'required'),
    ('export', ['--checkpoint', 'c.pt'], '--out', 'required'),
    ('ingest', ['--strict'], '--bags', 'required'),
    ('train', ['--bags', 'b', '--config', 'params/train/state_cpu.yaml', '--out', 'x', '--set',
               'k=7', 'bacth_size=256'], '--set bacth_size=256', "did you mean 'batch_size'"),
    ('train', ['--bags', 'b', '--config', 'params/train/state_cpu.yaml', '--out', 'x', '--set',
               'k=-1'], '--set k=-1', 'k must be a positive integer, got -1'),
    ('train', ['--bags', 'b', '--config', 'params/train/state_cpu.yaml', '--out', 'x', '--set',
               'num_updates=5', '--updates', '7'], '--set num_updates=5', 'both set num_updates'),
    ('loop', ['--task', 'Cheetah-Run-v0', '--config', 'params/train/state_cpu.yaml', '--out',
              'x', '--set', 'critic_context_grad=maybe'], '--set critic_context_grad=maybe',
     'must be true or false'),
    ('loop', ['--task', 'Cheetah-Run-v0', '--config', 'params/train/state_cpu.yaml', '--out',
              'x', '--set', 'k'], '--set k', 'expected KEY=VALUE'),
    ('sweep', ['--tasks', 'Cheetah-Run-v0', '--methods', 'zeus', '--out', 'x', '--set',
               'alpah_psi=0.5,1.0'], '--set alpah_psi=0.5,1.0', "did you mean 'alpha_psi'"),
]


@pytest.mark.parametrize(('command', 'argv', 'flag', 'hint'), BAD_VALUES,
                         ids=[f'{c}-{f}' for c, _a, f, _h in BAD_VALUES])
def test_a_bad_value_is_one_line_naming_the_flag_and_the_choices(
        command: str, argv: list[str], flag: str, hint: str, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    """Exit 2, one stderr line `zeus <cmd>: ... <flag> ... <choices/nearest>`, no traceback."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'b').mkdir()  # --bags b exists: a missing path is refused before --set is read
    assert _run(command, argv) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f'zeus {command}: ') and flag in err and hint in err, err
    assert not (tmp_path / 'x').exists()


@pytest.mark.parametrize('command', ['collect', 'loop', 'train', 'eval'])
def test_help_lists_the_task_names(command: str, capsys: pytest.CaptureFixture) -> None:
    """--help of every command taking --task names every task family."""
    assert _run(command, ['--help']) == 0
    text = ' '.join(capsys.readouterr().out.split())
    for name in TASK_NAMES:
        # argparse may wrap a name at its hyphens: compare without the wrapping spaces
        assert name in text.replace('- ', '-'), (command, name)


def test_schedule_is_spelled_one_way_in_every_help(capsys: pytest.CaptureFixture) -> None:
    """`zeus collect` and `zeus loop` show the same grammar; loop's default is written in it."""
    from zeus_ros.offline.rollout import parse_schedule

    _run('loop', ['--help'])
    text = capsys.readouterr().out
    assert 'switch:train:every_episodes=1' in text and 'values=train' not in text
    assert parse_schedule('switch:train:every_episodes=1') == {
        'kind': 'switch', 'values': 'train', 'every_episodes': 1}


def test_demo_offers_every_task_family(capsys: pytest.CaptureFixture) -> None:
    """Every registered family is a demo --task choice (Sawyer without a zoo checkpoint)."""
    _run('demo', ['--help'])
    text = ' '.join(capsys.readouterr().out.split())
    for name in TASK_NAMES:
        assert name in text, name
    assert _run('demo', ['--task', 'Sawyer-Peg-v0', '--no-frozen']) == 2
    err = capsys.readouterr().err
    assert 'Sawyer-Peg-v0 has no zoo checkpoint' in err and '--random-policy' in err


def test_train_config_is_found_in_the_package_share_from_any_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--config params/train/state_cpu.yaml works outside the repository; a typo names both."""
    from zeus_ros.learning.errors import ConfigError
    from zeus_ros.offline.training.train import read_config

    monkeypatch.chdir(tmp_path)
    assert read_config(Path('params/train/state_cpu.yaml')).method
    with pytest.raises(ConfigError, match=r'--config params/train/nope.yaml: not found in .* '
                       'nor in the package share'):
        read_config(Path('params/train/nope.yaml'))


def test_old_positional_spellings_still_work(tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    """`zeus recover BAG` and `zeus report FOLDER` (the old spelling) equal the flags."""
    missing = tmp_path / 'nothing'
    assert _run('recover', [str(missing)]) == 1
    positional = capsys.readouterr().err
    assert _run('recover', ['--bags', str(missing)]) == 1
    assert capsys.readouterr().err == positional
    assert _run('report', [str(missing), '--out', str(tmp_path / 'r')]) == 2
    positional = capsys.readouterr().err
    assert _run('report', ['--folder', str(missing), '--out', str(tmp_path / 'r')]) == 2
    assert capsys.readouterr().err == positional


def _documented_commands(text: str) -> list[tuple[str, list[str]]]:
    """Every `zeus <command> --flag ...` line of the bash blocks of a markdown text."""
    import re

    found = []
    for block in re.findall(r'```bash\n(.*?)```', text, flags=re.DOTALL):
        joined = block.replace('\\\n', ' ')
        for line in joined.splitlines():
            line = line.split('#', 1)[0].strip()
            if line.startswith('zeus ') and len(line.split()) > 1:
                words = line.split()
                found.append((words[1], [w.split('=')[0] for w in words if w.startswith('--')]))
    return found


@pytest.mark.parametrize('doc', ['README.md', 'docs/usage.md', 'docs/training.md',
                                 'docs/recording.md'])
def test_the_docs_use_only_commands_and_flags_the_help_lists(
        doc: str, capsys: pytest.CaptureFixture) -> None:
    """Docs and --help say the same: every documented command and flag exists."""
    text = (Path(__file__).resolve().parents[1] / doc).read_text()
    helps: dict[str, str] = {}
    for command, flags in _documented_commands(text):
        if command in ('--help', '-h'):
            continue
        assert command in SUBCOMMANDS, (doc, command)
        if command not in helps:
            assert _run(command, ['--help']) == 0
            helps[command] = capsys.readouterr().out
        for flag in flags:
            if flag != '--help':
                assert flag in helps[command], (doc, command, flag)


def test_readme_names_every_command() -> None:
    """The guide's `zeus --help` comment and executables table list every user command.

    The internal ones (the trainer's `continual-round`) dispatch but stay out of both and of
    `zeus --help`.
    """
    text = (Path(__file__).resolve().parents[1] / 'docs' / 'usage.md').read_text()
    comment = next(line for line in text.splitlines() if line.startswith('zeus --help'))
    row = next(line for line in text.splitlines() if line.startswith('| `zeus` |'))
    for name in SUBCOMMANDS:
        listed = name not in INTERNAL
        assert (f' {name} ' in comment.replace('/', ' ') + ' ') == listed, name
        assert (f'`{name}`' in row) == listed, name
        assert (f'\n  {name} ' in usage()) == listed, name


@pytest.mark.parametrize(('command', 'args', 'flag'), [
    ('train', ['--bags', 'b', '--config', 'c.yaml', '--out', 'o', '--threads', '-2'], '--threads'),
    ('loop', ['--out', 'o', '--rounds', '0'], '--rounds'),
    ('launch', ['--domain-id', '999'], '--domain-id'),
    ('demo', ['--seeds', 'abc'], '--seeds'),
    ('adaptation', ['--checkpoint', 'x.pt', '--episodes', '0'], '--episodes'),
    ('inspect', ['--refresh', '-1'], '--refresh'),
    ('sweep', ['--out', 'o', '--retries', '-1'], '--retries'),
    ('eval', ['--checkpoint', 'x.pt', '--episodes', '0'], '--episodes'),
    ('collect', ['--task', 'Cheetah-Bias-v0', '--steps', '-5', '--out', 'o'], '--steps'),
    ('export', ['--checkpoint', 'x.pt', '--out', 'y.pt', '--readout-steps', '-1'],
     '--readout-steps'),
])
def test_numeric_flags_out_of_range_are_one_line_exit_2(
        command: str, args: list[str], flag: str, capsys: pytest.CaptureFixture) -> None:
    """A negative thread count or zero rounds is refused before anything starts."""
    assert _run(command, args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f'zeus {command}: argument {flag}: ') and '\n' not in err
    assert 'must be' in err or 'is not an integer' in err


def test_a_config_without_its_size_names_the_missing_keys(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`method: zeus` alone would train the paper's GPU-sized networks: refused, keys named.

    With `base:` the rest comes from the named config, so the same two lines train.
    """
    only = tmp_path / 'only_method.yaml'
    only.write_text('method: zeus\n')
    assert _run('train', ['--bags', str(tmp_path), '--config', str(only), '--out',
                          str(tmp_path / 'o')]) == 2
    err = capsys.readouterr().err
    assert 'no k, context_dim, feature_dim, hidden_dim, batch_size, num_updates' in err
    assert 'base: state_cpu.yaml' in err and len(err.strip().splitlines()) == 1
    from zeus_ros.offline.training.train import read_config

    based = tmp_path / 'based.yaml'
    state_cpu = Path(__file__).resolve().parents[1] / 'params' / 'train' / 'state_cpu.yaml'
    based.write_text(f'base: {state_cpu}\nmethod: no_context\n')
    config = read_config(based)
    assert (config.method, config.hidden_dim) == ('no_context', 256)
