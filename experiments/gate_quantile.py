"""Where the gated actor hands over (issue 47): one continual round per gate setting, offline.

A continual round's candidate acts with the deployed actor where psi is familiar and with a
trained copy where it is novel (zeus_ros/learning/gated_actor.py); the hand-over starts at the
`quantile` of the train contexts' own novelty scores and is complete at `ramp` x that. This
re-runs one recorded round of a live drift run (its request.json: the same splits, rehearsal
and settings) as a *first* round from the zoo checkpoint, once per setting, and evaluates each
candidate in process on the scenario's values and the family's train values on seeds no gate
and no reference uses (9000), so a setting is chosen here and reported on the live runs'
reference seeds (7000, benchmarks/bench_continual.py).

    python experiments/gate_quantile.py --scenario run --setting 0.995:1.5 0.95:1.5 \
        --request out/continual/run_alone1/continual/rec_continual/round_011/request.json \
        --out out/gate_quantile/run

Each setting takes 3-5 min on one core (4,000 updates, the round's gate, the evaluation).
Writes gate_quantile.csv in --out (one row per setting; resumable: a setting already there is
skipped).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path
import sys
from typing import Any

from drift_scenarios import bench_continual
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
EVAL_SEED = 9000
"""Seeds for choosing: neither a gate (300 + 1000 r, + 500) nor the references (7000) use them."""
EPISODES = 5


def one_setting(request: dict[str, Any], scenario: str, quantile: float, ramp: float,
                out: Path) -> dict[str, Any]:
    """Train and gate one first-round candidate with the gate at (quantile, ramp); evaluate it."""
    import torch

    from zeus_ros.learning import gated_actor
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts, split_values
    from zeus_ros.offline.training.continual import run_round
    from zeus_ros.system.continual_settings import ContinualSettings

    torch.set_num_threads(1)
    gated_actor.GATE_QUANTILE, gated_actor.GATE_RAMP = quantile, ramp
    out.mkdir(parents=True, exist_ok=True)
    answer = run_round(request['first_checkpoint'], request['new_bags'], request['splits'], out,
                       out / 'history.jsonl', ContinualSettings(**request['settings']),
                       first_checkpoint=request['first_checkpoint'],
                       rehearsal_folder=request['rehearsal'], round_number=1)
    bench = bench_continual()
    task, _, values = bench.SCENARIOS[scenario]
    name = bench._context_name(task)
    agent = InferenceAgent.from_checkpoint(answer['candidate'])
    row: dict[str, Any] = {'quantile': quantile, 'ramp': ramp, 'gate_gain': answer['gain'],
                           'gate_se': answer['se'], 'deployed': answer['deploy']}
    for split, contexts in (('scenario', [{name: v} for v in values]),
                            ('train', split_values(task, 'train'))):
        returns = np.array([r['return'] for r in evaluate_contexts(
            agent, contexts, episodes=EPISODES, seed=EVAL_SEED, progress=False)])
        per_value = returns.reshape(len(contexts), -1).mean(1)
        row[f'{split}_return'] = round(float(per_value.mean()), 2)
        row[f'{split}_per_value'] = ' '.join(f'{v:.1f}' for v in per_value)
    print(json.dumps(row), flush=True)
    return row


def main() -> int:
    """Run the settings not yet in --out's table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--request', type=Path, required=True,
                        help="a live round's request.json (its splits and rehearsal must exist)")
    parser.add_argument('--scenario', choices=sorted(bench_continual().SCENARIOS), required=True)
    parser.add_argument('--setting', nargs='+', default=['0.995:1.5', '0.95:1.5'],
                        help='QUANTILE:RAMP pairs')
    parser.add_argument('--out', type=Path, required=True)
    args = parser.parse_args()
    request = json.loads(args.request.read_text('utf8'))
    table = args.out / 'gate_quantile.csv'
    rows = list(csv.DictReader(table.open())) if table.is_file() else []
    done = {(float(r['quantile']), float(r['ramp'])) for r in rows}
    for setting in args.setting:
        quantile, ramp = (float(x) for x in setting.split(':'))
        if (quantile, ramp) in done:
            continue
        rows.append(one_setting(request, args.scenario, quantile, ramp,
                                args.out / f'q{quantile:g}_r{ramp:g}'))
        with table.open('w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=list(rows[-1]))
            writer.writeheader()
            writer.writerows(rows)
    print(f'wrote {table}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
