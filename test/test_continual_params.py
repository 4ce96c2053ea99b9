"""The continual trainer's parameters: described, ranged, refused when bad (issue 48, item 4).

Its `SPECS` table says each parameter's meaning, range and whether it may change live; the
round's settings take their defaults and descriptions from ContinualSettings (one place). A bad
value stops `continual_trainer_node` at start with one line and exit 2, and `ros2 param set`
(here: the same callbacks in process) refuses it with the reason.
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
import re
import shutil

import pytest

from ros_harness import REPO, ProcessGroup, fresh_domain_id, require_ros, ros_context

BAD = [
    ('margin:=-5.0', 'parameter margin must be >= 0.0, got -5.0'),
    ('threads:=0', 'parameter threads must be >= 1, got 0'),
    ('checkpoint:=/nonexistent.pt', "parameter checkpoint '/nonexistent.pt' is not a file"),
    ('corrupt_rounds:=[-1]', 'parameter corrupt_rounds must hold values >= 0, got [-1]'),
    ('novelty_fraction:=1.5', 'parameter novelty_fraction must be <= 1.0, got 1.5'),
    ('recording:=""', 'parameter recording is required'),
    ('margni:=1.0', "unknown parameter(s) ['margni']"),
]


def test_every_trainer_parameter_has_a_description_and_a_range() -> None:
    """0 parameters without both; the settings' texts are ContinualSettings' docstrings."""
    require_ros()
    from zeus_ros.nodes.continual_node import DEFAULTS, SETTINGS, SPECS
    from zeus_ros.nodes.params import _descriptor, range_text
    from zeus_ros.system.continual_settings import ContinualSettings, field_docs

    docs = field_docs(ContinualSettings)
    assert set(docs) == {f.name for f in fields(ContinualSettings)} - {'seed'}
    missing = [name for name, spec in SPECS.items()
               if not spec.description.strip() or not range_text(spec)]
    assert missing == []
    for name, spec in SPECS.items():
        descriptor = _descriptor(spec)
        assert descriptor.read_only is not spec.live, name
        if isinstance(spec.default, int | float) and not isinstance(spec.default, bool):
            assert spec.low is not None, name
            assert descriptor.integer_range or descriptor.floating_point_range, name
    for name in SETTINGS:
        assert SPECS[name].default == getattr(ContinualSettings(), name), name
        assert SPECS[name].description.startswith(docs[name]), name
        assert SPECS[name].live, name
    assert {name: spec.default for name, spec in SPECS.items()} == DEFAULTS


def test_the_guide_lists_every_trainer_parameter_with_its_range() -> None:
    """docs/usage.md's trainer table: one row per parameter, with the range SPECS gives."""
    require_ros()
    from zeus_ros.nodes.continual_node import SPECS
    from zeus_ros.nodes.params import range_text

    guide = (REPO / 'docs' / 'usage.md').read_text()
    section = guide[guide.index('## Continual deployment'):]
    section = section[:section.index('\n## ')]
    rows = {match[0]: match[1] for match in re.findall(
        r'^\| `(\w+)` \| [^|]* \| ([^|]*) \|', section, flags=re.MULTILINE)}
    for name, spec in SPECS.items():
        assert name in rows, name
        assert rows[name].strip() == range_text(spec).replace('|', '&#124;'), name


@pytest.mark.parametrize(('param', 'needle'), BAD, ids=[p.split(':=')[0] for p, _ in BAD])
def test_a_bad_parameter_stops_the_trainer_with_one_line(
        ros_processes: ProcessGroup, tmp_path: Path, param: str, needle: str) -> None:
    """The installed executable: exit 2, one `error:` line naming the parameter."""
    executable = shutil.which('continual_trainer_node')
    assert executable, 'continual_trainer_node is not installed: run scripts/setup.sh'
    checkpoint = tmp_path / 'deployed.pt'
    checkpoint.write_bytes(b'not read at start')
    label = f'trainer-param-{param.split(":=")[0]}'
    process = ros_processes.start(label, [
        executable, '--ros-args', '-p', f'recording:={tmp_path / "rec"}',
        '-p', f'checkpoint:={checkpoint}', '-p', param])
    assert process.wait(timeout=60) == 2, ros_processes.log_text(label)
    log = ros_processes.log_text(label)
    assert log.startswith('error: continual_trainer: ') and log.count('\n') == 1, log
    assert needle in log, log


def test_live_sets_are_checked_and_applied(tmp_path: Path) -> None:
    """Out of range or read-only: refused with the reason; a round's setting: applied.

    The same callbacks serve `ros2 param set`; a change is a `parameters` line in the history.
    """
    require_ros()
    from rclpy.parameter import Parameter

    from zeus_ros.nodes.continual_node import ContinualTrainer
    from zeus_ros.system.continual_settings import read_history

    checkpoint = tmp_path / 'deployed.pt'
    checkpoint.write_bytes(b'not read at start')
    with ros_context(fresh_domain_id()) as context:
        node = ContinualTrainer(context=context, cli_args=[
            '--ros-args', '-p', f'recording:={tmp_path / "rec"}',
            '-p', f'checkpoint:={checkpoint}', '-p', 'margin:=0.5'])
        try:
            assert node.settings.margin == 0.5

            def refused(name: str, value: object) -> str:
                [result] = node.set_parameters([Parameter(name, value=value)])
                assert not result.successful, (name, value)
                return str(result.reason)

            # rclpy checks the descriptor's range first: its own words, with the range
            reason = refused('margin', -5.0)
            assert 'margin out of range' in reason and 'Min: 0.0' in reason, reason
            reason = refused('threads', 0)
            assert 'threads out of range' in reason and 'Min: 1,' in reason, reason
            assert 'read-only' in refused('checkpoint', '/nonexistent.pt')
            assert 'read-only' in refused('nice', 5)
            assert 'corrupt_rounds must hold values >= 0' in refused('corrupt_rounds', [-2])
            assert node.settings.margin == 0.5 and node.p['threads'] == 1
            assert not read_history(node.history)

            results = node.set_parameters([Parameter('margin', value=2.5),
                                           Parameter('episodes', value=5),
                                           Parameter('force_rounds', value=[3])])
            assert all(r.successful for r in results), [r.reason for r in results]
            assert (node.settings.margin, node.settings.episodes) == (2.5, 5)
            assert list(node.p['force_rounds']) == [3]
            changed: dict[str, object] = {}
            for record in read_history(node.history):  # one line per parameter set
                assert record['event'] == 'parameters', record
                changed.update(record['changed'])
            assert changed == {'margin': 2.5, 'episodes': 5, 'force_rounds': [3]}
        finally:
            node.destroy_node()
