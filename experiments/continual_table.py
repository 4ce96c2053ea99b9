"""The drift scenarios' table: every kept bench_continual run, fixed against --continual.

Reads docs/results/continual_drift/<scenario>_<run>/ (summary.csv, references.csv, as
benchmarks/bench_continual.py writes them), prints a Markdown table and writes scenarios.csv.

    python experiments/continual_table.py
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / 'docs' / 'results' / 'continual_drift'


def rows(root: Path) -> list[dict[str, object]]:
    """One row per kept run with both modes: live last third, decisions, in-process gap."""
    out = []
    for folder in sorted(p for p in root.iterdir() if (p / 'summary.csv').is_file()):
        modes = {r['mode']: r for r in csv.DictReader((folder / 'summary.csv').open())}
        if 'continual' not in modes or 'first_decision_s' not in modes['continual']:
            continue  # no run of this benchmark (the earlier design's files)
        cont = modes['continual']
        fixed = modes.get('fixed')
        row: dict[str, object] = {
            'run': folder.name, 'scenario': cont.get('scenario', ''),
            'burners': cont.get('burners', '0'),
            'continual': float(cont['last_third_return']),
            'continual_se': float(cont['last_third_se']),
            'swaps': int(cont['swaps']), 'refusals': int(cont['refusals']),
            'rollbacks': int(cont['rollbacks']), 'first_decision_s': cont['first_decision_s'],
            'trainer_share': float(cont['trainer_share']),
            'p99_idle_ms': float(cont['p99_idle_ms']), 'p99_busy_ms': float(cont['p99_busy_ms'])}
        if fixed is not None:
            diff = row['continual'] - float(fixed['last_third_return'])  # type: ignore[operator]
            se = math.hypot(float(cont['last_third_se']), float(fixed['last_third_se']))
            row.update({'fixed': float(fixed['last_third_return']),
                        'fixed_se': float(fixed['last_third_se']), 'diff': diff,
                        'diff_se': se, 'z': diff / se if se else float('nan')})
        refs = folder / 'references.csv'
        if refs.is_file():
            table = list(csv.DictReader(refs.open()))
            deployed = [r for r in table if r['checkpoint'].startswith('deployed')]
            zoo, oracle, plain = table[0], table[1], table[2]
            row.update({'zoo_inprocess': float(zoo['scenario_return']),
                        'oracle_inprocess': float(oracle['scenario_return']),
                        'no_context_inprocess': float(plain['scenario_return'])})
            if deployed:
                last = _running_at_the_end(folder, deployed)
                row.update({'last_deployed_inprocess': float(last['scenario_return']),
                            'gap_closed': float(last['gap_closed']),
                            'worst_train_change': min(float(r['worst_train_change'])
                                                      for r in deployed),
                            'train_allowed': min(float(r['worst_train_allowed'])
                                                 for r in deployed)})
        out.append(row)
    return out


def _running_at_the_end(folder: Path, deployed: list[dict[str, str]]) -> dict[str, str]:
    """The deployed checkpoint's row that ran last: its last swap, unless rolled back."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from zeus_ros.system.continual_settings import read_history, resume_point

    point = resume_point(read_history(folder / 'history.jsonl'))
    name = None if point.deployed is None else point.deployed.stem
    return next((r for r in deployed if r['checkpoint'] == f'deployed {name}'), deployed[-1])


def main() -> int:
    """Print the table; write scenarios.csv beside the runs."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--root', type=Path, default=ROOT)
    args = parser.parse_args()
    table = rows(args.root)
    fields: list[str] = []  # first seen first: the same column order on every run
    for row in table:
        fields += [key for key in row if key not in fields]
    with (args.root / 'scenarios.csv').open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(table)
    print('| run | last third, fixed / continual (per segment) | continual - fixed | swaps / '
          'refusals / rollbacks | first decision | in process at the scenario values: zoo / '
          'best reference / last deployed (gap closed) | worst train change (allowed) | '
          'p99 idle / busy |')
    print('|---|---|---|---|---|---|---|---|')
    for r in table:
        live = (f"{r['fixed']:.1f} ± {r['fixed_se']:.1f} / {r['continual']:.1f} ± "
                f"{r['continual_se']:.1f}" if 'fixed' in r else
                f"- / {r['continual']:.1f} ± {r['continual_se']:.1f}")
        diff = (f"{r['diff']:+.1f} ± {r['diff_se']:.1f} ({r['z']:.1f} s.e.)"
                if 'diff' in r else '-')
        best = max(r.get('oracle_inprocess', -1e9), r.get('no_context_inprocess', -1e9))
        inproc = (f"{r['zoo_inprocess']:.1f} / {best:.1f} / {r['last_deployed_inprocess']:.1f} "
                  f"({r['gap_closed']:.2f})" if 'last_deployed_inprocess' in r else '-')
        train = (f"{r['worst_train_change']:+.1f} ({r['train_allowed']:.1f})"
                 if 'worst_train_change' in r else '-')
        print(f"| {r['run']} | {live} | {diff} | {r['swaps']} / {r['refusals']} / "
              f"{r['rollbacks']} | {r['first_decision_s']} s | {inproc} | {train} | "
              f"{r['p99_idle_ms']:.1f} / {r['p99_busy_ms']:.1f} ms |")
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
