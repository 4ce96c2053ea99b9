"""`zeus adaptation`: a checkpoint's value of adaptation next to the zoo's, paired."""

from __future__ import annotations

from pathlib import Path

import pytest

from zeus_ros.cli.adaptation import main
from zeus_ros.offline.evaluation.adaptation import format_reports, measure_adaptation

ZOO = Path(__file__).resolve().parents[1] / 'checkpoints'


@pytest.mark.slow
def test_the_zoo_policy_adapts_and_plain_sac_has_nothing_to_freeze() -> None:
    """Live beats frozen beyond the range for the zoo's ZeUS; no_context gets returns only."""
    zeus = measure_adaptation(ZOO / 'cheetah_bias_v0' / 'zeus.pt', episodes=1, progress=False)
    plain = measure_adaptation(ZOO / 'cheetah_bias_v0' / 'no_context.pt', episodes=1,
                               progress=False)
    assert set(zeus.returns) == set(zeus.adaptation) == {'train', 'extrapolation'}
    mean, se = zeus.adaptation['extrapolation']
    assert mean > 2 * se > 0
    assert zeus.sensitivity >= 0.05
    assert plain.adaptation == {} and plain.returns['train'][0] < zeus.returns['train'][0]
    text = format_reports([('yours', plain), ('zoo', zeus)])
    assert text.splitlines()[0].split()[:2] == ['method', 'return']
    assert 'zoo: beyond the training range' in text and 'adapts' in text
    assert 'yours: beyond' not in text  # nothing to say without a context


def test_a_missing_checkpoint_is_one_line_exit_2(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """The error names the file; nothing else is measured."""
    with pytest.raises(SystemExit) as stop:  # refused while parsing, before torch loads
        main(['--checkpoint', str(tmp_path / 'nope.pt'), '--no-progress'])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith('zeus adaptation: ') and 'nope.pt' in err and len(err.splitlines()) == 1
