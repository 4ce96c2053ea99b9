"""The inspector's per-step log: context segments, returns, latency, figure and CSV."""

from __future__ import annotations

import numpy as np

from zeus_ros.step_log import StepLog, format_segments, plot_inspection


def make_log() -> StepLog:
    """Two context segments; rewards 1.0 then 2.0 per step; psi tracks the context."""
    log = StepLog(context_names=('torso_length',))
    for step in range(20):
        record = log.record(step)
        value = 0.6 if step < 10 else 1.2
        record.truth, record.segment = (value,), 0 if step < 10 else 1
        record.first = step == 0
        record.reward = 0.0 if step == 0 else (1.0 if step < 10 else 2.0)
        record.estimate = np.array([value, -value], np.float32)
        record.history_length = min(step, 5)
        record.t_observation, record.t_action = float(step), step + 0.002
    return log


def test_segments_sum_the_reward_earned_under_each_context() -> None:
    """Returns are credited to the context in force; the reset observation earns nothing."""
    first, second = make_log().segments()
    assert (first.context, first.steps, first.total_return) == ((0.6,), 10, 9.0)
    assert first.reward_per_step == 1.0
    assert (second.first_step, second.total_return) == (10, 20.0)
    assert second.context_error < 1e-6
    assert 'torso_length=1.2' in format_segments([first, second], ('torso_length',))


def test_latency_and_outputs(tmp_path) -> None:
    """Latency comes from receipt times; the CSV has a row per step and the PNG is written."""
    log = make_log()
    np.testing.assert_allclose(log.latencies_ms(), 2.0, rtol=1e-6)
    rows = log.save_csv(tmp_path / 'steps.csv').read_text().splitlines()
    assert len(rows) == 21 and rows[0].startswith('step,episode,segment')
    assert plot_inspection(log, tmp_path / 'fig.png').stat().st_size > 10_000
