"""Verified checkpoints (issue 49): a file whose sha256 is recorded is refused on a mismatch.

One bit flipped in a finite weight of the zoo's zeus.pt used to load and deploy without a word
(every tensor finite, every shape right). Now the card, the zoo index, a sidecar or
--expect-sha256 pin it: every entry point refuses it with one line naming both hashes, while
files nothing records (what `zeus train` and the continual trainer write) load as before.
"""

from __future__ import annotations

import hashlib
import importlib
import io
from pathlib import Path
import shutil
import subprocess

import pytest
import torch

from zeus_ros.cli import SUBCOMMANDS
from zeus_ros.integrity import pins_for
from zeus_ros.learning.checkpoint import load_checkpoint, save_checkpoint
from zeus_ros.learning.errors import CheckpointIntegrityError
from zeus_ros.learning.inference import InferenceAgent

from ros_harness import fresh_domain_id, python_module, ros_environment

torch.set_num_threads(1)  # as the nodes and the tools load; 2 threads crawl on a busy machine
REPO = Path(__file__).resolve().parents[1]
ZOO = REPO / 'checkpoints'
FAMILY = 'cheetah_bias_v0'
ZEUS = ZOO / FAMILY / 'zeus.pt'


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _flipped(data: bytes) -> tuple[bytes, str]:
    """The file with the lowest bit of one actor weight flipped (still finite), and its name."""
    payload = torch.load(io.BytesIO(data), map_location='cpu', weights_only=True)
    actor = payload['state']['modules']['actor']
    name = next(key for key, value in actor.items()
                if value.is_floating_point() and value.numel() >= 64)
    raw = actor[name].contiguous().numpy().tobytes()
    at = data.find(raw)
    assert at >= 0 and data.find(raw, at + 1) < 0, 'the tensor is stored once, uncompressed'
    flipped = bytearray(data)
    flipped[at + 4 * 17] ^= 0x01  # element 17, lowest mantissa bit (little-endian float32)
    return bytes(flipped), f'actor.{name}'


@pytest.fixture(scope='module')
def flipped() -> tuple[bytes, str]:
    """zeus.pt with one bit flipped inside a tensor."""
    return _flipped(ZEUS.read_bytes())


def _zoo_copy(root: Path, data: bytes, *, card: bool = True) -> Path:
    """A zoo root of its own: the index, `FAMILY/zeus.pt` holding `data`, its card."""
    (root / FAMILY).mkdir(parents=True)
    shutil.copyfile(ZOO / 'README.md', root / 'README.md')
    target = root / FAMILY / 'zeus.pt'
    target.write_bytes(data)
    if card:
        shutil.copyfile(ZEUS.with_suffix('.md'), target.with_suffix('.md'))
    return target


def _assert_refusal(message: str, path: Path, expected: str, found: str) -> None:
    """One line naming the file, both hashes and what to do."""
    assert '\n' not in message.strip(), message
    assert str(path) in message and 'refused' in message, message
    assert f'expected sha256 {expected}' in message and f'found {found}' in message, message
    assert 'restore' in message, message


def test_the_flipped_bit_is_silent_without_a_record(tmp_path: Path,
                                                    flipped: tuple[bytes, str]) -> None:
    """The attack: a lone copy (no card, no index) loads, finite, with a changed weight."""
    data, name = flipped
    lone = tmp_path / 'zeus.pt'
    lone.write_bytes(data)
    assert pins_for(lone) == []
    changed = load_checkpoint(lone, load_optimizers=False).agent.modules['actor'].state_dict()
    original = load_checkpoint(ZEUS, load_optimizers=False).agent.modules['actor'].state_dict()
    key = name.removeprefix('actor.')
    assert torch.isfinite(changed[key]).all()
    assert not torch.equal(changed[key], original[key])


def test_a_flipped_zoo_file_is_refused_naming_both_hashes(tmp_path: Path,
                                                          flipped: tuple[bytes, str]) -> None:
    """Card and index both pin it; with the card gone, the index's 12 digits still do."""
    data = flipped[0]
    target = _zoo_copy(tmp_path / 'zoo', data)
    recorded = _sha(ZEUS.read_bytes())
    with pytest.raises(CheckpointIntegrityError) as caught:
        InferenceAgent.from_checkpoint(target)
    _assert_refusal(str(caught.value), target, recorded, _sha(data))
    assert f'its card {target.with_suffix(".md")}' in str(caught.value)

    target.with_suffix('.md').unlink()
    with pytest.raises(CheckpointIntegrityError) as caught:
        load_checkpoint(target)
    _assert_refusal(str(caught.value), target, recorded[:12], _sha(data))
    assert f'the zoo index {tmp_path / "zoo" / "README.md"}' in str(caught.value)


def test_the_untouched_zoo_files_load_and_are_checked() -> None:
    """Every zoo file and the archive's carry a record, and match it."""
    for path in [ZEUS, ZOO / FAMILY / 'pixels_student.pt', ZOO / 'cheetah_run_v0_zeus_state.pt']:
        pins = pins_for(path)
        assert pins, path
        digest = _sha(path.read_bytes())
        assert all(digest.startswith(pin.digest) for pin in pins), path
    assert len(pins_for(ZEUS)) == 2  # its card and the zoo index
    InferenceAgent.from_checkpoint(ZEUS)


def test_an_untouched_copy_in_a_zoo_root_loads(tmp_path: Path) -> None:
    target = _zoo_copy(tmp_path / 'zoo', ZEUS.read_bytes())
    assert len(pins_for(target)) == 2
    InferenceAgent.from_checkpoint(target)


def test_a_link_to_a_flipped_zoo_file_is_checked_as_the_zoo_file(
        tmp_path: Path, flipped: tuple[bytes, str]) -> None:
    target = _zoo_copy(tmp_path / 'zoo', flipped[0])
    link = tmp_path / 'mine.pt'
    link.symlink_to(target)
    with pytest.raises(CheckpointIntegrityError):
        load_checkpoint(link)


def test_a_sidecar_pins_a_users_checkpoint(tmp_path: Path) -> None:
    """Wrong sidecar: refused, naming it; right one: loads; one without a hash: refused."""
    data = ZEUS.read_bytes()
    mine = tmp_path / 'mine.pt'
    mine.write_bytes(data)
    sidecar = tmp_path / 'mine.pt.sha256'
    wrong = _sha(b'something else')
    sidecar.write_text(f'{wrong}  mine.pt\n')
    with pytest.raises(CheckpointIntegrityError) as caught:
        InferenceAgent.from_checkpoint(mine)
    _assert_refusal(str(caught.value), mine, wrong, _sha(data))
    assert f'its sidecar {sidecar}' in str(caught.value)
    assert 'sha256sum mine.pt > mine.pt.sha256' in str(caught.value)

    sidecar.write_text(f'{_sha(data).upper()}  mine.pt\n')  # as sha256sum writes it, any case
    InferenceAgent.from_checkpoint(mine)

    sidecar.write_text('not a hash\n')
    with pytest.raises(CheckpointIntegrityError, match='holds no sha256') as caught:
        load_checkpoint(mine)
    assert '\n' not in str(caught.value)


def test_expect_sha256_pins_a_file(tmp_path: Path) -> None:
    data = ZEUS.read_bytes()
    mine = tmp_path / 'mine.pt'
    mine.write_bytes(data)
    InferenceAgent.from_checkpoint(mine, expect_sha256=_sha(data))
    wrong = 'ab' * 32
    with pytest.raises(CheckpointIntegrityError) as caught:
        InferenceAgent.from_checkpoint(mine, expect_sha256=wrong)
    _assert_refusal(str(caught.value).replace('check that', 'restore or check that'), mine,
                    wrong, _sha(data))
    assert '--expect-sha256' in str(caught.value)


def test_trainer_checkpoints_without_a_record_load_unhashed(tmp_path: Path) -> None:
    """`zeus train` and the continual trainer's rounds have no card: nothing to compare."""
    agent = load_checkpoint(ZEUS, load_optimizers=False).agent
    deployed = tmp_path / 'continual' / 'deployed'
    deployed.mkdir(parents=True)
    path = save_checkpoint(deployed / 'round_001_0123456789ab.pt', agent, step=5)
    assert pins_for(path) == []
    assert load_checkpoint(path, load_optimizers=False).step == 5


def test_export_over_a_stale_card_writes_a_new_one(tmp_path: Path) -> None:
    """Re-exporting replaces the file its old card recorded: the new card records the new one."""
    from zeus_ros.offline.evaluation.export import export

    out = tmp_path / 'export.pt'
    out.write_bytes(b'an older export')
    out.with_suffix('.md').write_text(f'| file | 0.01 MB, sha256 `{_sha(b"an older export")}` |\n')
    pt, card = export(ZEUS, out, summaries={})
    assert _sha(pt.read_bytes()) in card.read_text()
    load_checkpoint(pt)


def _run_cli(command: str, argv: list[str]) -> int:
    main = importlib.import_module(SUBCOMMANDS[command][0]).main
    try:
        return int(main(argv) or 0)
    except SystemExit as stop:
        return int(stop.code or 0)


def test_zeus_eval_refuses_it_in_one_line_exit_2(tmp_path: Path,
                                                 flipped: tuple[bytes, str]) -> None:
    """A real `zeus eval` process: exit 2, one line on stderr, no traceback, nothing written."""
    target = _zoo_copy(tmp_path / 'zoo', flipped[0])
    done = subprocess.run(python_module('zeus_ros.cli', 'eval', '--checkpoint', str(target),
                                        '--out', str(tmp_path / 'eval'), '--no-progress'),
                          capture_output=True, text=True, timeout=120, check=False, cwd=REPO)
    assert done.returncode == 2, done.stderr
    line = done.stderr.strip()
    assert len(line.splitlines()) == 1 and 'Traceback' not in done.stderr, done.stderr
    assert line.startswith('zeus eval: checkpoint ')
    _assert_refusal(line, target, _sha(ZEUS.read_bytes()), _sha(flipped[0]))
    assert not (tmp_path / 'eval').exists()


@pytest.mark.parametrize(('command', 'argv'), [
    ('adaptation', ['--against', 'none', '--no-progress']),
    ('demo', ['--task', 'Cheetah-Bias-v0', '--seeds', '1']),
    ('launch', ['--task', 'Cheetah-Bias-v0', '--no-progress', '--timeout', '5']),
])
def test_adaptation_demo_and_launch_refuse_it(tmp_path: Path, flipped: tuple[bytes, str],
                                       capsys: pytest.CaptureFixture[str], command: str,
                                       argv: list[str]) -> None:
    """Each says it in one line and exits 2 before it measures or starts anything."""
    target = _zoo_copy(tmp_path / 'zoo', flipped[0])
    out = ['--out', str(tmp_path / 'demo')] if command == 'demo' else []
    assert _run_cli(command, ['--checkpoint', str(target), *argv, *out]) == 2
    line = capsys.readouterr().err.strip()
    assert len(line.splitlines()) == 1, line
    _assert_refusal(line, target, _sha(ZEUS.read_bytes()), _sha(flipped[0]))


def test_expect_sha256_on_the_command_line(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    mine = tmp_path / 'mine.pt'
    shutil.copyfile(ZEUS, mine)
    assert _run_cli('eval', ['--checkpoint', str(mine), '--expect-sha256', 'abc']) == 2
    assert 'is not a sha256 (64 hex digits' in capsys.readouterr().err
    assert _run_cli('demo', ['--checkpoint', str(mine), '--expect-sha256', 'cd' * 32,
                             '--out', str(tmp_path / 'demo')]) == 2
    err = capsys.readouterr().err
    assert f'expected sha256 {"cd" * 32} (--expect-sha256), found {_sha(ZEUS.read_bytes())}' \
        in err, err
    assert _run_cli('eval', ['--checkpoint', str(mine), str(mine), '--out', str(tmp_path / 'e'),
                             '--expect-sha256', 'cd' * 32]) == 2
    assert 'pins one checkpoint file' in capsys.readouterr().err


def test_the_node_loader_refuses_it_also_when_the_bytes_are_shared(
        tmp_path: Path, flipped: tuple[bytes, str]) -> None:
    """The nodes' loader (start and live `checkpoint` changes) refuses with the node's name.

    Nodes of one process share an agent by sha256: the same bytes loaded first from a file
    nothing records, then under a zoo name that records other bytes, are still refused.
    """
    from zeus_ros.nodes.agent_loader import load_inference_agent

    params = {'torch_threads': 1, 'device': 'cpu', 'task': ''}
    lone = tmp_path / 'lone.pt'
    lone.write_bytes(flipped[0])
    held = load_inference_agent('policy', {**params, 'checkpoint': str(lone)})
    target = _zoo_copy(tmp_path / 'zoo', flipped[0])
    with pytest.raises(ValueError, match=r'^context_estimator: checkpoint .* refused') as caught:
        load_inference_agent('context_estimator', {**params, 'checkpoint': str(target)})
    _assert_refusal(str(caught.value), target, _sha(ZEUS.read_bytes()), held.sha256)
    assert load_inference_agent('policy', {**params, 'checkpoint': str(ZEUS)}).sha256 == \
        _sha(ZEUS.read_bytes())


def test_a_policy_node_given_the_flipped_file_exits_2(tmp_path: Path,
                                                      flipped: tuple[bytes, str]) -> None:
    """A real node process: one line, exit 2, before it publishes anything."""
    target = _zoo_copy(tmp_path / 'zoo', flipped[0])
    done = subprocess.run(
        python_module('zeus_ros.nodes.policy_node', '--ros-args', '-p',
                      f'checkpoint:={target}'),
        env=ros_environment(fresh_domain_id()), capture_output=True, text=True, timeout=60,
        check=False, cwd=REPO)
    assert done.returncode == 2, done.stderr
    assert 'Traceback' not in done.stderr, done.stderr
    lines = [line for line in done.stderr.splitlines() if 'refused' in line]
    assert len(lines) == 1, done.stderr
    _assert_refusal(lines[0], target, _sha(ZEUS.read_bytes()), _sha(flipped[0]))
