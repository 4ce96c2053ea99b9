"""The demo's value of adaptation: paired per segment, split by the training range."""

from __future__ import annotations

from pathlib import Path

import pytest

from zeus_ros.cli.demo_summary import (
    adaptation_rows,
    plot_adaptation,
    summarize_adaptation,
    write_rows,
)
from zeus_ros.step_log import SegmentSummary


def _segment(index: int, value: float, total: float, steps: int = 20) -> SegmentSummary:
    return SegmentSummary(segment=index, context=(value,), first_step=20 * index,
                          last_step=20 * index + steps - 1, steps=steps, total_return=total,
                          reward_per_step=total / steps)


def test_segments_pair_by_index_and_split_into_training_and_beyond(tmp_path: Path) -> None:
    """Gains are live - frozen of the same segment; short and unmatched segments are dropped."""
    live = [_segment(0, 0.2, -10.0), _segment(1, 0.5, -20.0), _segment(2, 0.2, -12.0),
            _segment(3, 0.5, -1.0, steps=1)]
    frozen = [_segment(0, 0.2, -14.0), _segment(1, 0.5, -30.0), _segment(2, 0.2, -13.0),
              _segment(3, 0.5, -2.0, steps=1)]
    rows = adaptation_rows(0, live, frozen, [(0.2,), (0.3,)], min_steps=20)
    assert [(r.segment, r.in_training_range, r.gain) for r in rows] == [
        (0, True, 4.0), (1, False, 10.0), (2, True, 1.0)]
    rows += adaptation_rows(1, live[:2], frozen[:1], [(0.2,)], min_steps=20)
    summary, sentence = summarize_adaptation(rows, every=20)
    mean, _se, n = summary['stats']['train']
    assert n == 3 and mean == pytest.approx(3.0)
    assert summary['stats']['beyond'][2] == 1 and summary['seed_totals'] == [15.0, 4.0]
    assert sentence.startswith('Adapting earned 4.8 ± ')
    assert 'beyond the training range +10.0 (1 segment)' in sentence
    assert write_rows(rows, ['motor_bias'], tmp_path / 'v.csv').read_text().count('\n') == 5
    assert plot_adaptation(rows, ['motor_bias'], tmp_path / 'v.png', 't').stat().st_size > 1000


def test_no_matching_segment_says_so() -> None:
    """Nothing to compare is a sentence, not a crash or a NaN table."""
    summary, sentence = summarize_adaptation([], every=20)
    assert 'no value of adaptation' in sentence and summary['seeds'] == []
