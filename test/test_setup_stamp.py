"""scripts/setup.sh skips the colcon build when nothing it reads changed (issue 52, item 9).

The stamp holds scripts/build_inputs.sh's hash: these tests pin what moves that hash (a .msg,
setup.py, a data file added) and what must not (a Python source, linked by --symlink-install;
an edited params file, linked file by file), on a copy of the inputs.
"""

from __future__ import annotations

from pathlib import Path
import shutil
import subprocess

ROOT = Path(__file__).resolve().parents[1]


def _tree(tmp_path: Path) -> Path:
    """The build's inputs copied to tmp_path/repo (the zoo: its index and one file)."""
    repo = tmp_path / 'repo'
    repo.mkdir()
    for name in ('setup.py', 'setup.cfg', 'package.xml'):
        shutil.copy(ROOT / name, repo / name)
    for folder in ('msg_defs', 'resource', 'params', 'launch', 'scripts'):
        shutil.copytree(ROOT / folder, repo / folder,
                        ignore=shutil.ignore_patterns('__pycache__'))
    (repo / 'checkpoints' / 'cheetah_bias_v0').mkdir(parents=True)
    shutil.copy(ROOT / 'checkpoints' / 'zoo.yaml', repo / 'checkpoints' / 'zoo.yaml')
    (repo / 'checkpoints' / 'cheetah_bias_v0' / 'zeus.md').write_text('card\n')
    (repo / 'zeus_ros').mkdir()
    (repo / 'zeus_ros' / 'module.py').write_text('A = 1\n')
    return repo


def _hash(repo: Path) -> str:
    done = subprocess.run(['bash', str(ROOT / 'scripts' / 'build_inputs.sh'), str(repo)],
                          capture_output=True, text=True, check=True, timeout=120)
    digest = done.stdout.strip()
    assert len(digest) == 64, done
    return digest


def test_the_build_hash_moves_with_what_colcon_reads(tmp_path: Path) -> None:
    """A changed .msg, setup.py or a new params file rebuild; Python or params edits do not."""
    repo = _tree(tmp_path)
    first = _hash(repo)
    assert _hash(repo) == first  # nothing changed: the build is skipped
    (repo / 'zeus_ros' / 'module.py').write_text('A = 2\n')
    (repo / 'zeus_ros' / 'new.py').write_text('B = 1\n')
    config = next((repo / 'params' / 'train').glob('*.yaml'))
    config.write_text(config.read_text() + '# edited\n')
    assert _hash(repo) == first, 'sources and linked data files need no build'
    message = next((repo / 'msg_defs' / 'msg').glob('*.msg'))
    message.write_text(message.read_text() + 'float64 added\n')
    after_msg = _hash(repo)
    assert after_msg != first, 'a changed .msg must rebuild zeus_msgs'
    (repo / 'params' / 'train' / 'mine.yaml').write_text('{}\n')
    after_params = _hash(repo)
    assert after_params != after_msg, 'a new data file must be installed'
    (repo / 'setup.py').write_text((repo / 'setup.py').read_text() + '\n# changed\n')
    assert _hash(repo) != after_params


def test_setup_writes_the_stamp_only_after_a_good_build() -> None:
    """The skip is keyed on that hash, and a failed build leaves no stamp to skip on."""
    text = (ROOT / 'scripts' / 'setup.sh').read_text()
    build = text.index('colcon --log-base')
    assert 'scripts/build_inputs.sh' in text[:build]
    assert text.index('rm -f "$STAMP"') < build < text.index('echo "$INPUTS" > "$STAMP"')
