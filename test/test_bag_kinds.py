"""Recordings say what they are; `zeus bags` lists them; `zeus train --bags` chooses by kind.

Issue 52 item 5: retraining "from what it recorded" took the continual trainer's rehearsal
along. Real (tiny) bags of `zeus collect`, relabelled and placed as a launch places them.
"""

from __future__ import annotations

from pathlib import Path
import shutil

import pytest

from zeus_ros.bags.kinds import (
    LABEL_FILE,
    BagLabel,
    bag_kind,
    choose_bags,
    read_label,
    write_label,
)
from zeus_ros.cli import bags as bags_cli
from zeus_ros.cli import collect, train

from tiny_config import TINY, write_config

TASK = 'Cheetah-Bias-v0'


@pytest.fixture(scope='module')
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """bags/ as a user's machine holds it: every kind, two of them from before bags said it."""
    root = tmp_path_factory.mktemp('kinds') / 'bags'
    collected = root / 'collected'
    assert collect.main(['--task', TASK, '--steps', '80', '--schedule',
                         'switch:values=train,every=20', '--out', str(collected),
                         '--no-progress']) == 0
    bag = collected / 'bag_000'
    places = {'zeus_20260101_120000/zeus_20260101_120000_000': BagLabel('manual', task=TASK),
              'continual_20260101_130000/continual_20260101_130000_000':
                  BagLabel('continual', task=TASK, checkpoint='zoo.pt'),
              'continual_rehearsal/abc_8000/bag_000': BagLabel('rehearsal', task=TASK),
              'old/bag_000': None,  # recorded before bags said what they are
              'continual_rehearsal/old_8000/bag_000': None}
    for place, label in places.items():
        shutil.copytree(bag, root / place)
        (root / place / LABEL_FILE).unlink()
        if label is not None:
            write_label(root / place, label)
    return root


def test_collect_labels_its_bag_and_old_bags_are_judged_by_folder(recording: Path) -> None:
    """Zeus collect writes 'collected'; an unlabelled rehearsal is still a rehearsal."""
    label = read_label(recording / 'collected' / 'bag_000')
    assert label is not None and (label.kind, label.task) == ('collected', TASK) and label.when
    assert bag_kind(recording / 'old' / 'bag_000') == ('manual', False)
    assert bag_kind(recording / 'continual_rehearsal' / 'old_8000' / 'bag_000') == \
        ('rehearsal', False)


def test_zeus_bags_lists_one_line_per_bag(recording: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """kind, task, steps, duration, when, checkpoint for each of the six bags."""
    assert bags_cli.main([str(recording)]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = [line.split() for line in lines[1:-1]]
    assert len(rows) == 6 and all(row[2] == '80' for row in rows)
    assert sorted(row[0] for row in rows) == ['collected', 'continual', 'manual', 'manual?',
                                              'rehearsal', 'rehearsal?']
    continual = next(row for row in rows if row[0] == 'continual')
    assert continual[1] == TASK and 'zoo.pt' in continual and continual[5][:2] == '20'
    assert bags_cli.main([str(recording / 'nothing')]) == 2


def test_train_takes_all_but_the_rehearsal_and_says_so_once(
        recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Default kinds: manual, collected, continual; --kinds rehearsal takes only those."""
    from zeus_ros.bags.recording import find_bags

    said: list[str] = []
    chosen = choose_bags(find_bags(recording), ('manual', 'collected', 'continual'), said.append)
    assert len(chosen) == 4 and not any('rehearsal' in p.parts for p in chosen)
    assert sum('say not what they are' in line for line in said) == 1
    config = write_config(tmp_path / 'tiny.yaml', TINY | {'num_updates': 2})
    common = ['--config', str(config), '--no-eval', '--no-progress', '--readout-steps', '0']
    assert train.main(['--bags', str(recording), '--out', str(tmp_path / 'run'), *common]) == 0
    err = capsys.readouterr().err
    assert err.count('say not what they are') == 1 and '2 rehearsal' in err
    from zeus_ros.learning.checkpoint import load_checkpoint

    trained = load_checkpoint(tmp_path / 'run' / 'final.pt').extra['bags']
    assert len(trained) == 4 and not any('continual_rehearsal' in bag for bag in trained)
    assert train.main(['--bags', str(recording), '--kinds', 'rehearsal', '--out',
                       str(tmp_path / 'rehearsal'), *common]) == 0
    assert len(load_checkpoint(tmp_path / 'rehearsal' / 'final.pt').extra['bags']) == 2
    with pytest.raises(SystemExit):
        train.main(['--bags', str(recording), '--kinds', 'everything', '--out', 'x', *common])


def test_the_launch_tells_the_recorder_what_it_records() -> None:
    """--record: manual; --continual: continual; both with the task and the checkpoint."""
    from zeus_ros.system.launch_defaults import plan

    for continual, kind in ((False, 'manual'), (True, 'continual')):
        launch = plan(record=True, continual=continual, task=TASK)
        recorder = next(node for node in launch.nodes if node.name == 'recorder').parameters
        assert recorder['kind'] == kind and recorder['label_task'] == TASK
        assert str(recorder['label_checkpoint']).endswith('zeus.pt')


def test_the_live_recorders_writer_labels_the_bag(tmp_path: Path) -> None:
    """DurableBagWriter (the recorder's) writes the label as the bag opens."""
    from zeus_ros.bags.durable import DurableBagWriter

    writer = DurableBagWriter(tmp_path / 'split_000', pixels=False,
                              label=BagLabel('continual', task=TASK, checkpoint='c.pt'))
    writer.close()
    label = read_label(tmp_path / 'split_000')
    assert label is not None and (label.kind, label.checkpoint) == ('continual', 'c.pt')
