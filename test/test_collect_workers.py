"""`zeus collect --workers N`: N simulator processes, each its own bag, seeds from the run seed.

Ingest of the N bags equals ingest of N sequential collections with the derived seeds and step
counts (the Ray variant of the same check is in test_sweep.py, which starts Ray once).
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from zeus_ros.cli import collect
from zeus_ros.offline.data.ingest import ingest_bags
from zeus_ros.offline.training.collect_workers import split_steps, worker_seeds

TASK = 'Cheetah-Run-v0'
STEPS, SEED = 301, 5
COMMON = ['--task', TASK, '--schedule', 'switch:train:every=50', '--no-progress']


def sequential_bags(out: Path) -> Path:
    """The N collections one after another, with the seeds and steps the workers use."""
    for seed, steps in zip(worker_seeds(SEED, 2), split_steps(STEPS, 2), strict=True):
        assert collect.main([*COMMON, '--steps', str(steps), '--seed', str(seed), '--out',
                             str(out), '--append']) == 0
    return out


def assert_same_data(parallel: Path, sequential: Path) -> None:
    """Same episodes, every array equal (only the bag each came from differs)."""
    mine, theirs = ingest_bags(parallel), ingest_bags(sequential)
    assert len(mine.episodes) == len(theirs.episodes) > 1
    assert mine.num_transitions == theirs.num_transitions == STEPS - len(mine.episodes)
    for a, b in zip(mine.episodes, theirs.episodes, strict=True):
        for field in fields(a):
            x, y = getattr(a, field.name), getattr(b, field.name)
            if isinstance(x, np.ndarray):
                np.testing.assert_array_equal(x, y, err_msg=field.name)


def test_seeds_and_steps_are_derived_from_the_run() -> None:
    assert worker_seeds(7, 1) == [7]
    seeds = worker_seeds(7, 3)
    assert seeds == worker_seeds(7, 3) and len(set(seeds)) == 3 and 7 not in seeds
    assert split_steps(10, 3) == [4, 3, 3]


@pytest.mark.slow
def test_worker_processes_equal_sequential_collections(tmp_path: Path) -> None:
    out = tmp_path / 'parallel'
    assert collect.main([*COMMON, '--steps', str(STEPS), '--seed', str(SEED), '--out',
                         str(out), '--workers', '2']) == 0
    assert sorted(p.name for p in out.iterdir()) == ['bag_000', 'bag_001']
    assert_same_data(out, sequential_bags(tmp_path / 'sequential'))
    assert collect.main([*COMMON, '--steps', '3', '--out', str(tmp_path / 'x'),
                         '--workers', '4']) == 2
    for lag in ('-1', '17'):  # the policy node's context_lag range, refused before any work
        try:  # -1: argparse's range check exits; 17: collect's own check returns
            code = collect.main([*COMMON, '--steps', '3', '--out', str(tmp_path / 'x'),
                                 '--context-lag', lag])
        except SystemExit as stop:
            code = stop.code
        assert code == 2, lag
    assert not (tmp_path / 'x').exists()
