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

With --checkpoint the same probe runs in that agent's latent space as well: phi(o') from
(phi(o), a), which is what ZeUS's T predicts (config.model_target 'latent'). A context that
explains much of the state change but little of phi(o') is hidden from psi by the target.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from zeus_ros.learning.checkpoint import load_checkpoint
from zeus_ros.offline.data.ingest import ingest_bags


def transitions(bags: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """o, a, o' and the first context parameter of every transition of `bags` (rows)."""
    obs, actions, next_obs, contexts = [], [], [], []
    for episode in ingest_bags([bags]).episodes:
        steps = len(episode.action)
        obs.append(episode.obs[:steps])
        actions.append(episode.action)
        next_obs.append(episode.obs[1:steps + 1])
        contexts.append(episode.context[:steps, :1])
    return np.vstack(obs), np.vstack(actions), np.vstack(next_obs), np.vstack(contexts)


def latent(checkpoint: Path, obs: np.ndarray) -> np.ndarray:
    """phi(o) of the checkpoint's encoder, (N, feature_dim)."""
    encoder = load_checkpoint(checkpoint, load_optimizers=False).agent.modules['encoder']
    with torch.no_grad():
        return encoder(torch.as_tensor(obs, dtype=torch.float32)).numpy()


def context_share(inputs: np.ndarray, target: np.ndarray,
                  context: np.ndarray) -> tuple[float, float, float]:
    """R^2 without and with the context (and its products), and the residual share explained."""
    without, _ = r_squared(inputs, target)
    with_context, _ = r_squared(np.hstack([inputs, inputs * context, context]), target)
    return without, with_context, (with_context - without) / max(1 - without, 1e-12)


def r_squared(features: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray]:
    """R^2 of the least-squares affine fit, over all dimensions and per dimension."""
    design = np.hstack([features, np.ones((len(features), 1))])
    weights, *_ = np.linalg.lstsq(design, target, rcond=None)
    residual = (target - design @ weights).var(0)
    return float(1 - residual.sum() / target.var(0).sum()), 1 - residual / target.var(0)


def main() -> None:
    """Print, per bag folder, R^2 without and with the context (and in phi space)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('bags', nargs='+', type=Path, help="bag folders (a run's bags/)")
    parser.add_argument('--checkpoint', type=Path, default=None,
                        help="also probe phi(o') from (phi(o), a) with this agent's encoder")
    args = parser.parse_args()
    print('| bags | target | transitions | R^2 from (o, a) | with the context | residual '
          'variance explained by the context |\n|---|---|---|---|---|---|')
    for bags in args.bags:
        obs, action, next_obs, context = transitions(bags)
        context = (context - context.mean()) / max(float(context.std()), 1e-12)
        targets = {"o' - o": (np.hstack([obs, action]), next_obs - obs)}
        if args.checkpoint is not None:
            feat, next_feat = latent(args.checkpoint, obs), latent(args.checkpoint, next_obs)
            targets["phi(o')"] = (np.hstack([feat, action]), next_feat)
        for name, (inputs, target) in targets.items():
            without, with_context, explained = context_share(inputs, target, context)
            print(f'| {bags} | {name} | {len(inputs)} | {without:.3f} | {with_context:.3f} | '
                  f'{explained:.2f} |')


if __name__ == '__main__':
    main()
