"""Corrupted-reward drills: a round's candidate trained on negated rewards must be refused.

For each seed, a fresh drift recording of Cheetah-Bias-v0 (the zoo checkpoint acting at biases
0.6-0.9 beyond its train range, noise 0.1, 2 x 1,000 steps), then one default round
(`continual_round`, the shared rehearsal, the actor gated) whose rewards are negated
(`corrupt_rewards`), and the gate's decision on that round's fresh seeds. Writes drills.csv.

    python experiments/continual_drills.py --out docs/results/continual_drift/drills
"""

from __future__ import annotations

import argparse
import csv
from dataclasses import replace
from pathlib import Path
import sys
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / 'test'))


def main() -> int:
    """Drill every seed, print each decision, write drills.csv."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=[1, 2, 3, 4, 5])
    parser.add_argument('--work', type=Path, default=Path('out/continual_drills'))
    parser.add_argument('--out', type=Path, default=Path('out/continual_drills'))
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    from continual_fixtures import record

    from zeus_ros.offline.training.continual import ROUND_SEED, continual_round, rehearsal_bag
    from zeus_ros.system.continual_settings import ContinualSettings

    zoo = REPO / 'checkpoints' / 'cheetah_bias_v0' / 'zeus.pt'
    settings = ContinualSettings()
    rehearsal = rehearsal_bag(zoo, args.work / 'rehearsal', settings)
    rows = []
    for seed in args.seeds:
        folder = args.work / f'seed{seed}'
        bags = sorted((folder / 'drift').glob('drift_*')) or record(
            folder / 'drift', 'Cheetah-Bias-v0', [0.6, 0.7, 0.75, 0.8, 0.85, 0.9], zoo, 2,
            1000, every=200, seed=100 * seed)
        begin = time.perf_counter()
        round_settings = replace(settings, eval_seed=settings.eval_seed + seed * ROUND_SEED)
        result = continual_round(zoo, bags, bags, folder / 'round', folder / 'history.jsonl',
                                 round_settings, rehearsal=rehearsal, corrupt_rewards=True)
        gate = result.gate
        rows.append({'seed': seed, 'decision': 'deploy' if gate.deploy else 'refuse',
                     'gain': round(gate.gain, 2), 'se': round(gate.se, 2),
                     'required': round(gate.required, 2), 'reason': gate.reason,
                     'seconds': round(time.perf_counter() - begin, 1)})
        print(rows[-1], flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    with (args.out / 'drills.csv').open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    refused = sum(r['decision'] == 'refuse' for r in rows)
    print(f'{refused} of {len(rows)} corrupted-reward candidates refused')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
