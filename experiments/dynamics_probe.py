"""Issue 10: how much of a one-step state change does the context explain? (no learning).

    python experiments/dynamics_probe.py \
        runs/i10_motor/default/cheetah_motor_v0/oracle_s0/bags \
        runs/i10_ep/default/cheetah_run_v0/oracle_s0/bags

For each bag folder: a least-squares linear model of the state change o' - o from (o, a), and
the same with the context (standardised) and its products with o and a added. The R^2 gain is
what a model that knows the context can explain of one step and one that does not cannot: a
lower bound on what psi could learn from a transition (a linear model sees only part of it).
Why: the context loss and the models of ZeUS read the context from transitions; a family whose
one-step dynamics do not move with the context (Cheetah-Run-v0's torso length) gives psi
nothing to read there, whatever the method.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from zeus_ros.offline.data.ingest import ingest_bags


def transitions(bags: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(o, a) rows, o' - o and the first context parameter of every transition of `bags`."""
    inputs, deltas, contexts = [], [], []
    for episode in ingest_bags([bags]).episodes:
        steps = len(episode.action)
        inputs.append(np.hstack([episode.obs[:steps], episode.action]))
        deltas.append(episode.obs[1:steps + 1] - episode.obs[:steps])
        contexts.append(episode.context[:steps, :1])
    return np.vstack(inputs), np.vstack(deltas), np.vstack(contexts)


def r_squared(features: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray]:
    """R^2 of the least-squares affine fit, over all dimensions and per dimension."""
    design = np.hstack([features, np.ones((len(features), 1))])
    weights, *_ = np.linalg.lstsq(design, target, rcond=None)
    residual = (target - design @ weights).var(0)
    return float(1 - residual.sum() / target.var(0).sum()), 1 - residual / target.var(0)


def main() -> None:
    """Print, per bag folder, R^2 without and with the context."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('bags', nargs='+', type=Path, help="bag folders (a run's bags/)")
    args = parser.parse_args()
    print("| bags | transitions | R^2 of o' - o from (o, a) | with the context | residual "
          'variance explained by the context |\n|---|---|---|---|---|')
    for bags in args.bags:
        inputs, deltas, context = transitions(bags)
        context = (context - context.mean()) / max(float(context.std()), 1e-12)
        without, _ = r_squared(inputs, deltas)
        with_context, _ = r_squared(np.hstack([inputs, inputs * context, context]), deltas)
        explained = (with_context - without) / max(1 - without, 1e-12)
        print(f'| {bags} | {len(inputs)} | {without:.3f} | {with_context:.3f} | '
              f'{explained:.2f} |')


if __name__ == '__main__':
    main()
