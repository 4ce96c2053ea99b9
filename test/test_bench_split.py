"""bench_live_loop.py --out: the step's segments (--split), the bridge's latency, CSV, pictures."""

from __future__ import annotations

from pathlib import Path
import sys

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'benchmarks'))

from bench_live_loop import P99_TARGETS_MS, RATIO_TARGETS, SEGMENTS, bridge_latency, segment_times
from live_loop_plot import plot_segments, plot_targets, write_rows


def test_segments_add_up_to_the_period_and_skip_steps_not_seen_on_every_topic() -> None:
    rng = np.random.default_rng(0)
    feedback, context, action, t = {}, {}, {}, 0
    for step in range(200):
        feedback[step] = t
        context[step] = t + int(rng.integers(1, 5)) * 1_000_000
        action[step] = context[step] + 500_000
        t = action[step] + 250_000 + step * 1_000  # sim_bridge's part grows
    del context[50]  # a context the probe missed: step 50 leaves the split
    parts = segment_times({'feedback': feedback, 'context': context, 'action': action})
    kept = [k for k in range(199) if k != 50]
    period = np.mean([(feedback[k + 1] - feedback[k]) * 1e-6 for k in kept])
    total = sum(parts[f'seg_{name}_mean'] for name in SEGMENTS)
    assert abs(total - period) < 1e-9
    assert parts['seg_policy_p50'] == parts['seg_policy_p99'] == 0.5
    assert 1.0 <= parts['seg_estimator_p50'] <= 4.0
    assert parts['seg_sim_bridge_p99'] > parts['seg_sim_bridge_p50'] > 0.25


def test_rows_and_picture_are_written(tmp_path: Path) -> None:
    rows = [{'kind': kind, 'mode': mode, 'executor': 'events', 'lag': lag, 'round': n,
             'rate': 300.0, **{f'seg_{s}_mean': 1.0 + n for s in SEGMENTS},
             **{f'in_process_{s}_mean': 0.4 for s in SEGMENTS}}
            for kind in ('state', 'pixels') for mode in ('multi', 'single')
            for lag in (0, 1) for n in range(2)]
    rows.append({'kind': 'state', 'mode': 'single-quiet', 'executor': 'events', 'lag': 0,
                 'round': 0, 'rate': 500.0})  # no split: a row of the CSV, not of the picture
    write_rows(rows, tmp_path / 'rows.csv')
    lines = (tmp_path / 'rows.csv').read_text().splitlines()
    assert len(lines) == len(rows) + 1 and 'seg_estimator_mean' in lines[0]
    plot_segments(rows, SEGMENTS, tmp_path / 'split.png')
    assert (tmp_path / 'split.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_targets_picture_takes_rows_without_a_latency(tmp_path: Path) -> None:
    """A row whose p99 is nan (no probe, no bridge count) still gets its ratio drawn."""
    rows = [{'kind': 'state', 'mode': mode, 'executor': 'events', 'lag': 0, 'round': n,
             'ratio': 0.3 + 0.2 * n, 'p99': p99}
            for mode, p99 in (('multi', 2.5), ('single-quiet', float('nan'))) for n in range(2)]
    plot_targets(rows, RATIO_TARGETS, P99_TARGETS_MS, tmp_path / 'targets.png')
    assert (tmp_path / 'targets.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_bridge_latency_is_read_from_its_last_closing_line() -> None:
    """sim_bridge's own count, as its closing log line says; nan when it never said it."""
    log = ('[INFO] [sim_bridge]: max_steps=400 reached; counts {...}; observation -> action '
           'p50 0.81 ms p99 1.32 ms over 401 answered steps\n')
    assert bridge_latency(log) == {'p50_bridge': 0.81, 'p99_bridge': 1.32}
    assert all(np.isnan(v) for v in bridge_latency('the node was killed').values())
