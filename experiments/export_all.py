"""Export every finished comparison run to checkpoints/comparison/<group>/<method>_s<seed>.pt.

    python experiments/export_all.py [runs/exp] [--target checkpoints/comparison]

Each export is a deployment checkpoint with its card (measured returns from the run's
eval_<split>/summary.csv). Runs trained before checkpoints recorded their command and commit get
the equivalent experiments/run_one.sh command and LEGACY_COMMIT, the last commit that changed the
learning, training and collection code those runs used.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from zeus_ros.learning.checkpoint import load_checkpoint
from zeus_ros.offline.evaluation.eval_batch import group_name
from zeus_ros.offline.evaluation.export import export
from zeus_ros.offline.runs import read_state

LEGACY_COMMIT = 'a70cad4'


def main() -> None:
    """Export each run folder that finished training (its run state)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('root', type=Path, nargs='?', default=Path('runs/exp'))
    parser.add_argument('--target', type=Path, default=Path('checkpoints/comparison'))
    args = parser.parse_args()
    runs = [run for run in sorted(args.root.glob('*/*_s*/')) if read_state(run).trained]
    for run in tqdm(runs, desc='export', unit='run'):
        final = run / 'run' / 'final.pt'
        loaded = load_checkpoint(final, load_optimizers=False)
        task, method, seed = loaded.spec.task, loaded.config.method, loaded.config.seed
        rounds = len(list((run / 'bags').glob('bag_*')))
        every = 20 if task == 'Cheetah-Run-v1' else 100
        command = (f'ROUNDS={rounds} bash experiments/run_one.sh {task} {method} {seed}  '
                   f'# zeus loop --task {task} --config params/train/state_cpu.yaml --method '
                   f'{method} --seed {seed} --rounds {rounds} --random-steps 1500 --steps 2000 '
                   f'--updates 2000 --noise 0.2 --schedule switch:train:every={every}')
        target = args.target / group_name(task, loaded.step) / f'{method}_s{seed}.pt'
        export(final, target, evals=run, command=command, commit=LEGACY_COMMIT)


if __name__ == '__main__':
    main()
