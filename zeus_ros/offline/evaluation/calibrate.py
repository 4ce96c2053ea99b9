"""Calibrating the context read-out and novelty monitor on a rollout of the deployed policy.

The monitors themselves, and how they are stored in a checkpoint, are learning/readout.py (the
nodes apply them); fitting them needs the task's train contexts and the policy acting on them,
which is this layer's work (`zeus export --readout-steps`, scripts/build_zoo.py).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from zeus_ros.learning.readout import (
    NOVELTY_WINDOW,
    READOUT_STEPS,
    ContextReadout,
    NoveltyMonitor,
    fit_novelty,
    fit_readout,
)

__all__ = ['calibrate_readout', 'deployment_readout']


def calibrate_readout(agent: Any, *, steps: int = READOUT_STEPS, every: int | None = None,
                      seed: int = 1000, progress: bool = False
                      ) -> tuple[ContextReadout, NoveltyMonitor]:
    """Roll the agent through its train contexts; fit the read-out and the novelty monitor.

    Both on the same steps (switching mid-episode), with the same segments held back.

    `agent` is an InferenceAgent with a learned context. Only steps with a full history count
    (what the estimator publishes once an episode is k steps old).
    """
    from zeus_ros.offline.evaluation.evaluate import (
        default_switch_every,
        make_env,
        split_values,
        switch_schedule,
        switching_order,
    )
    from zeus_ros.offline.rollout import AgentPolicy, run_steps

    values = switching_order(split_values(agent.task, 'train'), seed)
    # Short enough that every value comes back at least twice (one of them can be held back),
    # long enough for a full history plus a settled novelty window in each segment.
    every = every or max(agent.k + NOVELTY_WINDOW + 5,
                         min(default_switch_every(agent.task), steps // (2 * len(values))))
    env, task = make_env(agent.task, switch_schedule(values, every), seed)
    try:
        trace = run_steps(env, task, AgentPolicy(agent, noise=0.0, seed=seed), steps,
                          desc='read-out', progress=progress)
    finally:
        task.close()
    if trace.psi is None or trace.psi.shape[1] == 0:
        raise ValueError(f'context read-out: a {agent.method} checkpoint has no learned context')
    full = trace.history_length >= agent.k
    fitted_on = (f'{int(full.sum())} steps of the policy on the train contexts of {agent.task}, '
                 f'switching every {every} steps, seed {seed}')
    episodes = np.cumsum(trace.first)[full]
    return (fit_readout(trace.psi[full], trace.context[full], agent.context_names,
                        trace.segment[full], fitted_on=fitted_on),
            fit_novelty(trace.psi[full], trace.context[full], trace.segment[full], episodes,
                        fitted_on=fitted_on))


def deployment_readout(agent: Any, steps: int = READOUT_STEPS
                       ) -> tuple[ContextReadout, NoveltyMonitor] | None:
    """The read-out and novelty monitor a deployment of `agent` (a ZeusAgent) carries.

    One rule for `zeus export` and `zeus train`, so a trained checkpoint deploys as an export
    does. None where there is nothing to fit: `steps` 0, pixels (every step would render), a
    method without a learned psi, or a robot's task (no simulator here). ValueError when the
    rollout is too short to fit them.
    """
    from sim_bridge.registry import is_simulated
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.learning.methods import method_objective

    if steps <= 0 or agent.spec.obs_kind != 'state' or not is_simulated(agent.spec.task) or \
            method_objective(agent.config.method).context_source != 'psi':
        return None
    return calibrate_readout(InferenceAgent(agent), steps=steps)
