"""Issue 10, session 5: the context-precision table of docs/results.md, from compare_variants' CSV.

    python experiments/context_precision_table.py docs/results/issue10/cheetah_run_v1.csv \
        > docs/results/issue10/cheetah_run_v1_context_precision.md

The oracle with an exact, a persistent (10-step) and a fresh-per-use error on its normalised
context, next to ZeUS k10, k10 with an MLP head and k20: share of the headroom recovered (paired
gain) and value of adaptation (frozen at the mean) per split.
"""

from __future__ import annotations

import csv
import sys

from sim_bridge.presets import SPLITS

ROWS = (('default', 'oracle', 'oracle (exact context)', '∞'),
        ('oracle_noise03_slow', 'oracle', 'oracle + persistent error 0.3', '3.3'),
        ('oracle_noise06_slow', 'oracle', 'oracle + persistent error 0.6', '1.7'),
        ('oracle_noise03', 'oracle', 'oracle + fresh error 0.3 per use', '3.3'),
        ('oracle_noise06', 'oracle', 'oracle + fresh error 0.6 per use', '1.7'),
        ('k10', 'zeus', 'ZeUS k10 (default)', None),
        ('k10_mlp_head', 'zeus', 'ZeUS k10, MLP head', None),
        ('k20', 'zeus', 'ZeUS k20', None))
"""(variant, method, label, nominal spread/noise; None: the measured one)."""


def main() -> None:
    """Print the markdown table."""
    with open(sys.argv[1], newline='') as handle:
        rows = list(csv.DictReader(handle))
    header = ' | '.join(f'{s}: share of headroom (gain) | {s}: value of adaptation (mean)'
                        for s in SPLITS)
    print(f'| context fed to the policy | seeds | {header} | spread/noise (train) |')
    print('|---|---|' + '---|---|' * len(SPLITS) + '---|')
    for variant, method, label, nominal in ROWS:
        cells = {r['split']: r for r in rows if r['variant'] == variant and r['method'] == method}
        if set(cells) != set(SPLITS):
            continue
        line = [label, cells['train']['seeds']]
        for split in SPLITS:
            line += [f"{cells[split]['share']} ({cells[split]['gain']})",
                     cells[split]['adaptation_mean']]
        line.append(nominal or cells['train']['spread_noise'])
        print('| ' + ' | '.join(str(x) for x in line) + ' |')


if __name__ == '__main__':
    main()
