"""Learning curves from the bags: mean reward per step of every collection round, per method.

    python experiments/collection_curves.py runs/exp/walker_walk_v0 --out docs/results/x

Round 1 is the uniform-random warm-up; round r > 1 was collected by the policy after
2,000 (r - 1) updates plus exploration noise, under the collection schedule. Mean and standard
error over seeds of every trained run (its run state) go to collection.csv and collection.png;
methods whose curves coincide (e.g. several at 0) keep their own marker and dash.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path
import warnings

import numpy as np

from zeus_ros.offline.data.ingest import ingest_bags
from zeus_ros.offline.evaluation.metrics import overlap_style, write_csv
from zeus_ros.offline.evaluation.report import RUN_NAME, mean_se, method_order_key
from zeus_ros.offline.runs import read_state


def main() -> None:
    """Read every finished run's bags; write the per-round table and plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('folder', type=Path)
    parser.add_argument('--out', type=Path, required=True)
    args = parser.parse_args()
    curves: dict[str, list[list[float]]] = defaultdict(list)
    for run in sorted(args.folder.glob('*_s*/')):
        match = RUN_NAME.match(run.name)
        if match is None or not read_state(run).trained:
            continue
        rounds = []
        for bag in sorted((run / 'bags').glob('bag_*')):
            with warnings.catch_warnings():
                warnings.simplefilter('ignore')
                episodes = ingest_bags([bag]).episodes
            rounds.append(float(np.concatenate([e.reward for e in episodes]).mean()))
        curves[match['method']].append(rounds)
    methods = sorted(curves, key=method_order_key)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for method in methods:
        length = min(len(r) for r in curves[method])
        for index in range(length):
            mean, se = mean_se([r[index] for r in curves[method]])
            rows.append({'method': method, 'round': index + 1, 'seeds': len(curves[method]),
                         'reward_per_step': mean, 'reward_per_step_se': se})
    write_csv(args.out / 'collection.csv', rows)
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6))
    for index, method in enumerate(methods):
        mine = [r for r in rows if r['method'] == method]
        ax.errorbar([r['round'] for r in mine], [r['reward_per_step'] for r in mine],
                    yerr=[r['reward_per_step_se'] for r in mine], label=method, capsize=3,
                    **overlap_style(index, len(methods)))
    ax.set_xticks(range(1, 1 + max((r['round'] for r in rows), default=1)))
    ax.set_xlabel('collection round (1 = uniform random)')
    ax.set_ylabel('reward per step (mean ± s.e.)')
    ax.set_title(f'{args.folder.name}: reward while collecting')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc='upper left', bbox_to_anchor=(1.0, 1.0))  # never over a line
    fig.tight_layout()
    fig.savefig(args.out / 'collection.png', dpi=110)
    plt.close(fig)
    for row in rows:
        print(f"{row['method']:<22} round {row['round']}: {row['reward_per_step']:.3f} "
              f"± {row['reward_per_step_se']:.3f}")


if __name__ == '__main__':
    main()
