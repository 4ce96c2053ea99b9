"""`zeus sweep` on the real Ray runtime (a local loopback-only instance, started once here).

Tiny trials (one round of 100 random steps, a few dozen updates, one evaluation split of
Cheetah-Run-v1's 40-step episodes): a 2x2 sweep finishes, equals the same trials run one after
another (two of them: each method and each seed once), and a rerun skips it; a trial killed
mid-run is retried and one that keeps failing is reported with its log; Ray's sockets stay on
loopback.
"""

from __future__ import annotations

from collections.abc import Iterator
import os
from pathlib import Path
import re
import signal
import subprocess
import threading
import time
from typing import Any

import pytest
import torch

from zeus_ros.cli import main as zeus_main
from zeus_ros.cli.sweep import main as sweep_main
from zeus_ros.learning.config import config_from_dict
from zeus_ros.offline.runs import read_state
from zeus_ros.offline.training.sweep import parse_seeds, parse_sets, plan, run_sweep
from zeus_ros.offline.training.trial import LoopProtocol, trial_steps

from tiny_config import TINY, config_fixture

torch.set_num_threads(1)  # as the trials' OMP_NUM_THREADS=1
pytestmark = pytest.mark.alone  # Ray runs two trials at once: both cores (xdist: see conftest)
TASK = 'Cheetah-Run-v1'
PROTOCOL = LoopProtocol(rounds=1, random_steps=100, updates=30, eval_episodes=1)
FLAGS = ['--rounds', '1', '--random-steps', '100', '--updates', '30', '--eval-episodes', '1',
         '--eval-splits', 'extrapolation']


@pytest.fixture(scope='module')
def ray_session() -> Iterator[None]:
    """One local Ray instance for the module (starting one takes 5-15 s)."""
    ray = pytest.importorskip('ray')
    from zeus_ros.offline.training.ray_runtime import start_ray

    assert start_ray(num_cpus=2)
    try:
        yield
    finally:
        ray.shutdown()


tiny_config = config_fixture(TINY)


def _trials(out: Path, methods: list[str], seeds: list[int],
            sets: list[dict[str, Any]] | None = None, protocol: LoopProtocol = PROTOCOL
            ) -> list[Any]:
    return plan([TASK], methods, seeds, sets or [{}], config_from_dict(TINY), out, protocol,
                ['extrapolation'])


def _weights(path: Path) -> dict[str, torch.Tensor]:
    state = torch.load(path, map_location='cpu', weights_only=False)['state']
    flat: dict[str, torch.Tensor] = {}

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, dict):
            for key, inner in value.items():
                walk(f'{prefix}.{key}', inner)
        elif isinstance(value, torch.Tensor):
            flat[prefix] = value

    walk('', state)
    return flat


def _descendants() -> set[int]:
    """The pids of this process and every process below it (Ray's servers and workers)."""
    children: dict[int, list[int]] = {}
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / 'stat').read_text().rsplit(')', 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    found, todo = set(), [os.getpid()]
    while todo:
        pid = todo.pop()
        found.add(pid)
        todo += children.get(pid, [])
    return found


def _non_loopback_sockets() -> list[str]:
    """`ss -tnpa` lines of our processes with an address off loopback (Ray must have some)."""
    ours = _descendants()
    lines = subprocess.run(['ss', '-tnpa'], capture_output=True, text=True,
                           check=True).stdout.splitlines()[1:]
    mine = [line for line in lines
            if any(int(pid) in ours for pid in re.findall(r'pid=(\d+)', line))]
    assert any('raylet' in line or 'gcs_server' in line for line in mine), lines
    loopback = re.compile(r'^(\[?(::ffff:)?127\.\d+\.\d+\.\d+\]?|\[::1\]|\*|0\.0\.0\.0)$')
    bad = []
    for line in mine:
        local, peer = (address.rsplit(':', 1)[0] for address in line.split()[3:5])
        if not loopback.match(local) or local in ('*', '0.0.0.0') or not loopback.match(peer):
            bad.append(line)  # off loopback, or listening on every interface
    return bad


def test_grid_parsing() -> None:
    assert parse_seeds('0-2,7') == [0, 1, 2, 7]
    assert parse_sets(['alpha_psi=0.5,1.0', 'k=3']) == [{'alpha_psi': 0.5, 'k': 3},
                                                         {'alpha_psi': 1.0, 'k': 3}]
    assert parse_sets([]) == [{}]
    for bad in (['alpha_psi'], ['k=1', 'k=2'], ['seed=3']):
        with pytest.raises(ValueError, match='--set'):
            parse_sets(bad)


@pytest.mark.slow
def test_a_2x2_sweep_equals_the_sequential_trials_and_a_rerun_skips_it(
        ray_session: None, tiny_config: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture) -> None:
    argv = ['--tasks', TASK, '--methods', 'zeus', 'no_context', '--seeds', '0-1', '--config',
            str(tiny_config), '--out', str(tmp_path / 'sweep'), *FLAGS]
    assert sweep_main(argv) == 0
    out = capsys.readouterr().out
    assert '4/4 done, 0 running, 0 failed' in out
    assert '| zeus | extrapolation | 2 |' in out and '| no_context | extrapolation | 2 |' in out
    group = tmp_path / 'sweep' / 'cheetah_run_v1'
    assert '| no_context | extrapolation | 2 |' in (tmp_path / 'sweep' / 'tables.md').read_text()
    assert (group / 'table.md').is_file()

    trials = _trials(tmp_path / 'sequential', ['zeus', 'no_context'], [0, 1])
    for trial in (trials[0], trials[-1]):  # zeus seed 0 and no_context seed 1, one by one
        for _what, args, _record in trial_steps(trial):  # the trial's commands, one by one
            assert zeus_main(args) == 0
        swept = group / trial.folder.name
        summary = 'eval_extrapolation/summary.csv'
        assert (trial.folder / summary).read_text() == (swept / summary).read_text(), trial.name
        mine, theirs = (_weights(f / 'run' / 'final.pt') for f in (trial.folder, swept))
        assert mine.keys() == theirs.keys() and mine
        assert all(torch.equal(mine[k], theirs[k]) for k in mine), trial.name

    stamps = {p: p.stat().st_mtime_ns for p in group.rglob('*') if p.is_file()}
    assert sweep_main(argv) == 0
    out = capsys.readouterr().out
    assert '4 finished before (skipped), 0 to run' in out and '0 ran, 4 skipped' in out
    assert all(p.stat().st_mtime_ns == t for p, t in stamps.items() if p.name != 'table.md'
               and p.suffix not in ('.csv', '.png', '.md'))
    assert sweep_main([*argv, '--updates', '31']) == 2  # another protocol: not mixed in
    assert 'was run with other settings (updates: 30 -> 31)' in capsys.readouterr().err


@pytest.mark.slow
def test_a_killed_trial_is_retried_and_a_failing_one_reported_with_its_log(
        ray_session: None, tmp_path: Path) -> None:
    """The device=cpu trial is killed once and retried; device=cuda:99 fails twice (no device).

    Ray's sockets stay on loopback meanwhile.
    """
    protocol = LoopProtocol(rounds=1, random_steps=100, updates=80, eval_episodes=1)
    trials = _trials(tmp_path, ['no_context'], [0], parse_sets(['device=cpu,cuda:99']), protocol)
    killed, cuda = trials
    lines: list[str] = []
    result: dict[str, Any] = {}
    sweep = threading.Thread(target=lambda: result.update(
        r=run_sweep(trials, cpus_per_trial=1, log=lines.append)))
    sweep.start()
    pid_file = killed.folder.with_name(killed.folder.name + '.pid')
    deadline = time.monotonic() + 120
    while not ((killed.folder / 'run').is_dir() and pid_file.is_file()):
        assert time.monotonic() < deadline and sweep.is_alive(), lines
        time.sleep(0.02)
    assert _non_loopback_sockets() == []
    os.kill(int(pid_file.read_text()), signal.SIGKILL)  # the pid of a step the sweep started
    sweep.join(timeout=240)
    assert not sweep.is_alive()
    outcome = result['r']
    assert outcome.done == [killed.name] and outcome.attempts[killed.name] == 2
    assert any('was killed by SIGKILL' in line and 'retrying (attempt 2)' in line
               for line in lines), lines
    assert 'extrapolation' in read_state(killed.folder).evaluated
    assert killed.log.read_text().count('== ') == 2  # one header per attempt
    assert list(outcome.failed) == [cuda.name] and outcome.attempts[cuda.name] == 2
    assert f'training exited with code 2 (log: {cuda.log})' in outcome.failed[cuda.name]
    assert 'device cuda:99' in cuda.log.read_text()
    assert lines[-1].startswith('sweep: 1/2 done, 0 running, 1 failed')


@pytest.mark.slow
def test_collect_workers_as_ray_tasks_equal_sequential_collections(ray_session: None,
                                                                   tmp_path: Path) -> None:
    from test_collect_workers import COMMON, SEED, STEPS, assert_same_data, sequential_bags

    from zeus_ros.cli import collect

    out = tmp_path / 'ray'
    assert collect.main([*COMMON, '--steps', str(STEPS), '--seed', str(SEED), '--out', str(out),
                         '--workers', '2', '--ray']) == 0
    assert_same_data(out, sequential_bags(tmp_path / 'sequential'))
