"""Issue 10: are psi's per-transition codes saturated? (why a psi can be flat for good).

    python experiments/psi_saturation.py --checkpoints \
        checkpoints/issue10_episodes/default/cheetah_motor_v0_10k \
        checkpoints/issue10_episodes/k10/cheetah_run_v1_50k [--out docs/results/issue10/x.csv]

psi encodes each transition with an MLP whose tanh output is averaged over the k transitions.
A code at +-1 passes no gradient (tanh' ~ 0): if every code of every history is there, psi is
the same for every context and no loss can change that. Per checkpoint, on its task's train
values (`zeus eval`'s protocol: deterministic episodes, evaluation seed 100): the share of codes
with |code| > 0.99, the share of code units that hardly move (std < 1e-3), psi's spread
between the values' means over its noise within episodes (as in `zeus eval`; scale-free, so a
collapsed psi's leftover 1e-5 variations can still give ratios above 1) and the absolute gap
between the mean psi of the two extreme values (what the actor, fed psi raw, can see).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from zeus_ros.offline.evaluation.eval_batch import find_checkpoints
from zeus_ros.offline.evaluation.evaluate import evaluate_contexts, split_values
from zeus_ros.offline.evaluation.metrics import write_csv

SATURATED = 0.99
"""|code| above this counts as saturated (tanh' < 0.02)."""


def saturation(path: Path, episodes: int) -> dict[str, Any] | None:
    """Code statistics of one checkpoint on its train values; None for a method without psi."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.diagnostics import (
        extreme_indices,
        policy_contexts,
        spread_over_noise,
    )

    agent = InferenceAgent.from_checkpoint(path)
    psi = agent.agent.modules.get('psi')
    if psi is None:
        return None
    codes: list[np.ndarray] = []

    def keep(_module: Any, _inputs: Any, output: torch.Tensor) -> None:
        codes.append(torch.tanh(psi.code_norm(output)).detach().reshape(
            -1, output.shape[-1]).numpy())

    hook = psi.transition.register_forward_hook(keep)
    traces: list = []
    try:
        evaluate_contexts(agent, split_values(agent.task, 'train'), episodes=episodes, seed=100,
                          progress=False, traces=traces)
    finally:
        hook.remove()
    every = np.concatenate(codes)
    contexts = [policy_contexts(t, agent) for t in traces]
    low, high = extreme_indices(split_values(agent.task, 'train'))
    return {'checkpoint': os.path.relpath(path), 'codes': len(every),
            'saturated': float(np.mean(np.abs(every) > SATURATED)),
            'still_units': float(np.mean(every.std(0) < 1e-3)),
            'spread_noise': spread_over_noise(contexts)[2],
            'extreme_gap': float(np.linalg.norm(contexts[high].mean(0) - contexts[low].mean(0)))}


def main() -> None:
    """Print a markdown table (and write a CSV with --out)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--checkpoints', nargs='+', type=Path, required=True,
                        help='checkpoint files or folders of them')
    parser.add_argument('--episodes', type=int, default=1, help='episodes per train value')
    parser.add_argument('--out', type=Path, help='CSV to write')
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = [row for path in find_checkpoints(args.checkpoints)
            if (row := saturation(path, args.episodes)) is not None]
    print('| checkpoint | codes at +-1 | code units that hardly move | psi spread / noise | '
          '|psi(lowest) - psi(highest)| |\n|---|---|---|---|---|')
    for row in rows:
        print(f'| {row["checkpoint"]} | {row["saturated"]:.3f} | {row["still_units"]:.2f} | '
              f'{row["spread_noise"]:.2f} | {row["extreme_gap"]:.2g} |')
    if args.out is not None:
        write_csv(args.out, rows)


if __name__ == '__main__':
    main()
