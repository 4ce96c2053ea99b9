"""How large is the learned context the policy sees? Spread of psi between and within contexts.

    python experiments/context_scale.py checkpoints/comparison/cheetah_run_v0_10k \
        --split train --out docs/results/cheetah_run_v0_10k/context_scale.csv

Per checkpoint (with a context encoder): one deterministic episode per context value of the split
(the `zeus eval` protocol, evaluation seed 100), then
- spread: mean pairwise distance between the per-value mean psi (what separates contexts),
- noise: mean over values of the per-dimension std of psi within the episode,
- norm: mean norm of the per-value mean psi.
The policy sees psi raw, so a spread of 1e-3 is a context signal 1,000x weaker than one of 1.
Writes the per-checkpoint CSV, and mean ± s.e. per method as markdown (same name, .md).
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.spatial.distance import pdist
from tqdm import tqdm

from zeus_ros.learning.inference import InferenceAgent
from zeus_ros.offline.evaluation.eval_batch import find_checkpoints
from zeus_ros.offline.evaluation.evaluate import (
    evaluate_contexts,
    mean_context_per_value,
    split_values,
)
from zeus_ros.offline.evaluation.metrics import write_csv
from zeus_ros.offline.evaluation.report import RUN_NAME, mean_se, method_order_key


def context_scale(path: Path, split: str) -> dict[str, float | str] | None:
    """Spread, noise and norm of psi for one checkpoint (None without a context encoder)."""
    agent = InferenceAgent.from_checkpoint(path)
    if agent.context_dim == 0 or agent.needs_true_context:
        return None  # no learned context: no_context, oracle
    values = split_values(agent.task, split)
    traces: list = []
    evaluate_contexts(agent, values, episodes=1, seed=100, progress=False, traces=traces)
    means = mean_context_per_value(traces, agent.k)
    if means is None:
        return None
    noise = np.mean([t.psi[t.history_length >= agent.k].std(0).mean() for t in traces])
    seed = RUN_NAME.match(path.stem)  # <method>_s<seed>.pt, as export_all names them
    return {'checkpoint': str(path), 'method': agent.method,
            'seed': int(seed['seed']) if seed else -1, 'split': split,
            'spread': float(pdist(means).mean()), 'noise': float(noise),
            'norm': float(np.linalg.norm(means, axis=1).mean())}


def main() -> None:
    """Measure every checkpoint given; write the CSV and print the per-method summary."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('checkpoints', type=Path, nargs='+', help='files or folders of *.pt')
    parser.add_argument('--split', default='train')
    parser.add_argument('--out', type=Path, required=True, help='CSV to write')
    args = parser.parse_args()
    rows = []
    for path in tqdm(find_checkpoints(args.checkpoints), desc='checkpoints', unit='ckpt'):
        row = context_scale(path, args.split)
        if row is not None:
            rows.append(row)
    if not rows:
        raise SystemExit(f'context_scale: no checkpoint with a context encoder in '
                         f'{[str(p) for p in args.checkpoints]}')
    write_csv(args.out, rows)
    by_method: dict[str, list[dict]] = defaultdict(list)
    for row in rows:
        by_method[str(row['method'])].append(row)
    lines = ['| method | seeds | psi spread between contexts | psi noise within an episode | '
             'spread / noise |', '|---|---|---|---|---|']
    for method in sorted(by_method, key=method_order_key):
        group = by_method[method]
        cells = [mean_se([float(r[key]) for r in group]) for key in ('spread', 'noise')]
        ratio = mean_se([float(r['spread']) / float(r['noise']) for r in group])
        lines.append(f'| {method} | {len(group)} | {cells[0][0]:.4f} ± {cells[0][1]:.4f} | '
                     f'{cells[1][0]:.4f} ± {cells[1][1]:.4f} | {ratio[0]:.1f} ± {ratio[1]:.1f} |')
    args.out.with_suffix('.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines))
    print(f'\nwrote {args.out} and {args.out.with_suffix(".md")}')


if __name__ == '__main__':
    main()
