"""Issue 10: what a trained psi carries, measured on its own run's bags (no environment needed).

    python experiments/psi_probe.py RUN [RUN ...] [--against EARLIER_RUN ...] [--batch 2048]

RUN is a run folder of experiments/run_one.sh (RUN/run/final.pt, RUN/bags/). For each run, on a
batch of histories sampled from its bags:
- reliability: per psi dimension, 1 - noise variance / total variance, the noise estimated
  without labels from psi(H_t) and psi(H_{t+1}) as the `reliability` normaliser does
  (learning/context.ContextNormalizer); its mean is printed;
- R^2: the share of the true context's variance a linear map of psi explains (labels used here
  only to measure, never in training);
- with --against (one earlier run per RUN, e.g. the 10k run a 20k run continued): how far psi
  moved between the two checkpoints on the same histories, as a fraction of its spread, raw and
  after the best rigid alignment (translation, rotation, scale): a small aligned drift with a
  large raw one would mean psi only turned, a large aligned drift that it changed shape.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from zeus_ros.learning.checkpoint import load_checkpoint
from zeus_ros.learning.context import ContextNormalizer
from zeus_ros.offline.training.train import load_data


def _psi(agent, batch) -> tuple[torch.Tensor, torch.Tensor]:
    """psi(H_t) and psi(H_{t+1}) of a batch, through the checkpoint's own encoder."""
    m = agent.modules
    with torch.no_grad():
        history, _ = agent.history_features(batch.hist_obs, batch.hist_action,
                                            batch.hist_reward, batch.hist_next_obs,
                                            batch.hist_mask)
        shifted = history.shifted(m['encoder'](batch.obs), agent.normalize_action(batch.action),
                                  batch.reward.float(), m['encoder'](batch.next_obs))
        return m['psi'](history), m['psi'](shifted)


def linear_r2(x: np.ndarray, y: np.ndarray) -> float:
    """Share of y's variance explained by an affine map of x (least squares)."""
    design = np.c_[x, np.ones(len(x))]
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    return float(1.0 - (y - design @ coef).var() / y.var())


def drift(before: np.ndarray, after: np.ndarray) -> tuple[float, float]:
    """RMS move of psi as a fraction of its spread: raw, and after the best rigid alignment."""
    b, a = before - before.mean(0), after - after.mean(0)
    spread = np.sqrt((a ** 2).sum(1).mean())
    raw = np.sqrt(((after - before) ** 2).sum(1).mean()) / spread
    u, s, vt = np.linalg.svd(b.T @ a)
    scale = s.sum() / (b ** 2).sum()
    aligned = np.sqrt(((a - scale * b @ (u @ vt)) ** 2).sum(1).mean()) / spread
    return float(raw), float(aligned)


def main() -> None:
    """Print the probe of each run."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('runs', type=Path, nargs='+')
    parser.add_argument('--against', type=Path, nargs='+', help='one earlier run per RUN')
    parser.add_argument('--batch', type=int, default=2048)
    args = parser.parse_args()
    if args.against and len(args.against) != len(args.runs):
        parser.error(f'--against needs one run per RUN ({len(args.runs)}), '
                     f'got {len(args.against)}')
    torch.set_num_threads(1)
    for i, run in enumerate(args.runs):
        loaded = load_checkpoint(run / 'run' / 'final.pt', load_optimizers=False)
        agent, config = loaded.agent, loaded.config
        if 'psi' not in agent.modules:
            parser.error(f'{run}: method {config.method} has no learned context to probe')
        _, replay = load_data(sorted((run / 'bags').iterdir()), config, None, 'cpu', 0)
        batch = replay.sample(args.batch)
        psi, next_psi = _psi(agent, batch)
        norm = ContextNormalizer(config.context_dim, momentum=1.0, noise_scale=config.k / 2)
        norm.update(psi, next_psi, batch.not_done)
        context = batch.context.double().numpy()
        r2 = [linear_r2(psi.double().numpy(), context[:, j]) for j in range(context.shape[1])]
        reliability = norm.reliability()
        line = (f'{run} ({loaded.step:,} updates): reliability {float(reliability.mean()):.2f}'
                f' (per dim {" ".join(f"{r:.2f}" for r in reliability.tolist())}); '
                f'R^2 true context {" ".join(f"{r:.2f}" for r in r2)}')
        if args.against:
            earlier = load_checkpoint(args.against[i] / 'run' / 'final.pt',
                                      load_optimizers=False)
            raw, aligned = drift(_psi(earlier.agent, batch)[0].double().numpy(),
                                 psi.double().numpy())
            line += (f'; since {args.against[i]} ({earlier.step:,}): drift {raw:.2f} x spread, '
                     f'{aligned:.2f} after rigid alignment')
        print(line, flush=True)


if __name__ == '__main__':
    main()
