"""Issue 10: every config variant of one task side by side, against no_context and the oracle.

    python experiments/compare_variants.py --task Cheetah-Run-v1 [--root runs/i10]
        [--evals out/i10] [--out docs/results/issue10] [--export checkpoints/issue10]
        [--splits train extrapolation] [--episodes 3] [--jobs 1] [--updates 20000]
        [--shipped checkpoints/issue10] [--variants default k10 ...] [--against k10 [default]]
        [--paired-with k10:zeus_no_context_loss]

For each variant folder under --root (default, paper, norm_only, ...: one training config each,
runs laid out by experiments/run_queue.sh as <root>/<variant>/<task>/<method>_s<seed>/), it
evaluates every finished run on every split with `zeus eval` (resumable; evaluation seed 100,
3 episodes per value, diagnostics), then writes one table per split: return, the paired gain
over `no_context` of the default protocol (same seeds), the share of the oracle's headroom it
recovers, and the adaptation diagnostics. With --export, each finished run is also shipped as a
deployment checkpoint with its card under <export>/<variant>/<group>/. --updates picks the budget:
10,000 (runs in <task>/), or a longer one (runs in <task>_<N>k/, as run_one.sh lays them out with
ROUNDS > 5); the tables of a longer budget are named <task>_<N>k. --paired-with VARIANT:METHOD
adds every row's difference to that one run set (return, value of adaptation against the train
mean, Spearman), paired by seed: a config against the ablation, say. With --shipped, variants that
have no runs under --root are evaluated from their shipped checkpoints instead (a fresh clone
regenerates the tables from checkpoints/issue10 alone).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from zeus_ros.offline.evaluation.eval_batch import evaluate_many, find_checkpoints, group_name
from zeus_ros.offline.evaluation.metrics import write_csv
from zeus_ros.offline.evaluation.report import (
    BOUND,
    REFERENCE,
    SPLIT_ORDER,
    mean_se,
    method_order_key,
    paired_difference,
    per_run,
    wall_time_table,
)
from zeus_ros.offline.runs import read_state

REFERENCE_VARIANT = 'default'
"""The variant whose no_context and oracle runs define the headroom."""


BASE_UPDATES = 10_000
"""The budget of the runs in <task>/ (run_one.sh's 5 rounds); longer ones live in <task>_<N>k/."""


def _task_folder(task: str, updates: int = BASE_UPDATES) -> str:
    name = task.lower().replace('-', '_')
    return name if updates == BASE_UPDATES else group_name(task, updates)


def evaluate_variant(root: Path, variant: str, task: str, evals: Path, *,
                     splits: list[str] | None, episodes: int, jobs: int,
                     updates: int = BASE_UPDATES, shipped: Path | None = None) -> Path | None:
    """Evaluate the finished runs of one variant at one budget; returns its tables' folder.

    Shipped checkpoints (`shipped`/<variant>/<group>/<method>_s<seed>.pt, which act exactly
    like the runs they came from) stand in for runs that are not under `root`, so the tables
    can be regenerated on a clone that holds only the shipped files.
    """
    runs = root / variant / _task_folder(task, updates)
    finals = [p / 'run' / 'final.pt' for p in sorted(runs.glob('*_s*/'))
              if read_state(p).trained]
    exported = shipped / variant / group_name(task, updates) if shipped is not None else None
    if exported is not None and exported.is_dir():
        trained = {p.parent.parent.name for p in finals}  # <method>_s<seed>
        finals += [p for p in sorted(exported.glob('*.pt')) if p.stem not in trained]
    if not finals:
        return None
    evaluate_many(find_checkpoints(finals), evals / variant, splits=splits, jobs=jobs,
                  progress=True, expect_task=task, probe_steps=0, seed=100,
                  episodes=episodes)
    group = evals / variant / group_name(task, updates)
    return group if group.is_dir() else None


def _cell(values: list[float], digits: int = 1) -> str:
    values = [v for v in values if np.isfinite(v)]
    if not values:
        return '-'
    mean, se = mean_se(values)
    return f'{mean:.{digits}f} ± {se:.{digits}f}'


def _floats(rows: list[dict[str, Any]], key: str) -> list[float]:
    out = []
    for row in rows:
        try:
            out.append(float(row[key]))
        except (KeyError, TypeError, ValueError):
            continue
    return out


PAIRED_METRICS = (('mean_return', 'return'),
                  ('adaptation_value_train_mean', "value of adaptation (train values' mean)"),
                  ('spearman', 'Spearman'))
"""Metrics --paired-with compares, (CSV column, title)."""


def paired_cells(runs: dict[str, list[dict[str, Any]]], variant: str, method: str, split: str,
                 paired_with: tuple[str, str]) -> dict[str, str]:
    """A row's runs minus the `paired_with` (variant, method) runs, per PAIRED_METRICS, by seed."""
    other_variant, other_method = paired_with
    if (variant, method) == paired_with:
        return {f'vs_{metric}': '-' for metric, _ in PAIRED_METRICS}
    theirs = [{**r, 'method': 'other'} for r in runs.get(other_variant, [])
              if r['method'] == other_method]
    mine = [{**r, 'method': 'mine'} for r in runs[variant] if r['method'] == method]
    cells = {}
    for metric, _ in PAIRED_METRICS:
        paired = paired_difference([*mine, *theirs], 'mine', 'other', split, metric)
        digits = 2 if metric == 'spearman' else 1
        cells[f'vs_{metric}'] = '-' if paired is None else (
            f'{paired[0]:.{digits}f} ± {paired[1]:.{digits}f} ({paired[2]})')
    return cells


def variant_rows(tables: dict[str, Path], against: Sequence[str] = (),
                 paired_with: tuple[str, str] | None = None) -> list[dict[str, Any]]:
    """One row per (split, variant, method) with the numbers of the comparison table.

    `against`: variants whose runs of the same method each row is also compared with, paired
    by seed ('vs_against', e.g. a new option against the default config); the first of them
    that has runs of the row's method is used (`k10 default`: zeus against k10's, the
    baselines against default's). `paired_with`: paired_cells' columns.
    """
    runs = {variant: per_run(folder) for variant, folder in tables.items()}
    reference = runs.get(REFERENCE_VARIANT, [])
    baselines = [r for r in reference if r['method'] in (REFERENCE, BOUND)]
    rows = []
    for variant, mine in runs.items():
        methods = sorted({r['method'] for r in mine}, key=method_order_key)
        for split in SPLIT_ORDER:
            headroom = paired_difference(baselines, BOUND, REFERENCE, split)
            for method in methods:
                cells = [r for r in mine if r['method'] == method and r['split'] == split]
                if not cells:
                    continue
                label = f'{method} ({variant})'
                combined = [*baselines, *({**r, 'method': label} for r in cells)]
                gain = (None if method == REFERENCE
                        else paired_difference(combined, label, REFERENCE, split))
                row = {'split': split, 'variant': variant, 'method': method,
                       'seeds': len(cells), 'return': _cell(_floats(cells, 'mean_return')),
                       'gain': '-' if gain is None else f'{gain[0]:.1f} ± {gain[1]:.1f}',
                       'gain_over_se': '-' if gain is None or gain[1] == 0
                       else f'{gain[0] / gain[1]:.1f}',
                       'share': '-' if gain is None or headroom is None or not headroom[0]
                       else f'{gain[0] / headroom[0]:.2f}',
                       'sensitivity': _cell(_floats(cells, 'sensitivity'), 3),
                       'spread_noise': _cell(_floats(cells, 'spread_noise'), 2),
                       'adaptation_other': _cell(_floats(cells, 'adaptation_value_other')),
                       'adaptation_mean': _cell(_floats(cells, 'adaptation_value_mean')),
                       'adaptation_train_mean': _cell(_floats(cells,
                                                              'adaptation_value_train_mean')),
                       'adaptation_steady': _cell(_floats(cells, 'adaptation_value_steady')),
                       'spearman': _cell(_floats(cells, 'spearman'), 2),
                       'headroom': '-' if headroom is None
                       else f'{headroom[0]:.1f} ± {headroom[1]:.1f}'}
                if against:
                    source = next((v for v in against if any(
                        r['method'] == method for r in runs.get(v, []))), None)
                    theirs = [{**r, 'method': 'against'} for r in runs.get(source, [])
                              if r['method'] == method and r['split'] == split]
                    paired = None if variant == source else paired_difference(
                        [*theirs, *({**r, 'method': 'mine'} for r in cells)], 'mine', 'against',
                        split)
                    row['vs_against'] = '-' if paired is None else \
                        f'{paired[0]:.1f} ± {paired[1]:.1f} ({paired[2]} seeds)'
                if paired_with is not None:
                    row.update(paired_cells(runs, variant, method, split, paired_with))
                rows.append(row)
    return rows


COLUMNS = (('variant', 'config'), ('method', 'method'), ('seeds', 'seeds'),
           ('return', 'return'), ('gain', f'gain over {REFERENCE} (paired)'),
           ('gain_over_se', 'gain / s.e.'), ('share', 'share of headroom'),
           ('sensitivity', 'context sensitivity'), ('spread_noise', 'spread / noise'),
           ('adaptation_other', 'value of adaptation (other extreme)'),
           ('adaptation_mean', 'value of adaptation (mean)'),
           ('adaptation_train_mean', "value of adaptation (train values' mean)"),
           ('adaptation_steady', 'value of adaptation (train mean, once the history is full)'),
           ('spearman', 'Spearman'))


def markdown(rows: list[dict[str, Any]], against: Sequence[str] = (),
             paired_with: tuple[str, str] | None = None) -> str:
    """One table per split, headroom in its heading."""
    columns = COLUMNS if not against else (
        *COLUMNS, ('vs_against', f'return vs the same method of {" or ".join(against)} '
                                 '(paired)'))
    if paired_with is not None:
        name = ':'.join(paired_with)
        columns = (*columns, *((f'vs_{metric}', f'{title} vs {name} (paired, seeds)')
                               for metric, title in PAIRED_METRICS))
    sections = []
    for split in SPLIT_ORDER:
        mine = [r for r in rows if r['split'] == split]
        if not mine:
            continue
        lines = [f'#### {split} (headroom {BOUND} - {REFERENCE}: {mine[0]["headroom"]})', '',
                 '| ' + ' | '.join(title for _, title in columns) + ' |',
                 '|' + '---|' * len(columns)]
        lines += ['| ' + ' | '.join(str(r[key]) for key, _ in columns) + ' |' for r in mine]
        sections.append('\n'.join(lines))
    return '\n\n'.join(sections) + '\n'


def plot(rows: list[dict[str, Any]], path: Path, title: str) -> None:
    """Return per config and method on each split, mean ± s.e. (what the tables say)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    splits = [s for s in SPLIT_ORDER if any(r['split'] == s for r in rows)]
    labels = list(dict.fromkeys(f'{r["method"]} ({r["variant"]})' for r in rows))
    fig, axes = plt.subplots(1, len(splits), figsize=(4.2 * len(splits), 0.38 * len(labels) + 1.6),
                             squeeze=False, sharey=True)
    for ax, split in zip(axes[0], splits, strict=True):
        for i, label in enumerate(labels):
            row = next((r for r in rows if r['split'] == split
                        and f'{r["method"]} ({r["variant"]})' == label), None)
            if row is None or row['return'] == '-':
                continue
            mean, se = (float(x) for x in row['return'].split(' ± '))
            ax.errorbar(mean, i, xerr=se, fmt='o', capsize=3)
        ax.set_yticks(range(len(labels)), labels, fontsize=8)
        ax.set_xlabel('episode return (mean ± s.e. over seeds)')
        ax.set_title(split, fontsize=10)
        ax.grid(alpha=0.3, axis='x')
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def export_runs(root: Path, variant: str, task: str, target: Path, evals: Path,
                updates: int = BASE_UPDATES, overwrite: bool = False) -> None:
    """Ship each finished run of the variant as a deployment checkpoint with its card.

    A run already shipped is left as it is unless `overwrite`: its card names the numbers it
    was shipped with, and a re-export would rewrite every committed checkpoint of the variant.
    """
    from zeus_ros.learning.checkpoint import load_checkpoint
    from zeus_ros.offline.evaluation.export import export

    for run in sorted((root / variant / _task_folder(task, updates)).glob('*_s*/')):
        final = run / 'run' / 'final.pt'
        if not read_state(run).trained or not final.is_file():
            continue
        loaded = load_checkpoint(final, load_optimizers=False)
        group = group_name(task, loaded.step)
        name = f'{loaded.config.method}_s{loaded.config.seed}'
        shipped = target / variant / group / f'{name}.pt'
        if shipped.is_file() and not overwrite:
            continue
        export(final, shipped, evals=evals / variant / group / name)


def _with_train_seconds(runs: list[dict[str, Any]], folder: Path) -> list[dict[str, Any]]:
    """Evaluation rows with the training seconds their run folder recorded (its run state)."""
    for run in runs:
        seconds = read_state(folder / f'{run["method"]}_s{run["seed"]}').train_seconds
        run['train_seconds'] = '' if seconds is None else f'{seconds:g}'
    return runs


def main() -> None:
    """Evaluate, compare and (optionally) export every variant of one task."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--task', required=True)
    parser.add_argument('--root', type=Path, default=Path('runs/i10'))
    parser.add_argument('--evals', type=Path, default=Path('out/i10'))
    parser.add_argument('--out', type=Path, default=Path('docs/results/issue10'))
    parser.add_argument('--export', type=Path, help='ship finished runs here (with cards); '
                        'runs shipped there already are kept unless --overwrite')
    parser.add_argument('--overwrite', action='store_true',
                        help='with --export: ship again the runs already shipped')
    parser.add_argument('--shipped', type=Path, action='append', default=[],
                        help='a folder of shipped checkpoints (<variant>/<group>/*.pt, e.g. '
                             'checkpoints/issue10): variants with no runs under --root are '
                             'evaluated from it; repeat it for several folders')
    parser.add_argument('--variants', nargs='+',
                        help=f'only these variants (default: all; {REFERENCE_VARIANT!r} holds the '
                             'no_context and oracle runs that define the headroom)')
    parser.add_argument('--against', nargs='+', default=[],
                        help='also compare each row with the same method of this variant, '
                             'paired by seed (e.g. k10, the default config); with several, the '
                             'first that has runs of the method (k10 default)')
    parser.add_argument('--paired-with', metavar='VARIANT:METHOD',
                        help='also give each row minus these runs (return, value of '
                             'adaptation, Spearman), paired by seed, e.g. '
                             'k10:zeus_no_context_loss')
    parser.add_argument('--splits', nargs='+', choices=SPLIT_ORDER,
                        help="default: every split the task's preset defines")
    parser.add_argument('--episodes', type=int, default=3, help='episodes per context value')
    parser.add_argument('--jobs', type=int, default=1, help='evaluations in parallel')
    parser.add_argument('--updates', type=int, default=BASE_UPDATES,
                        help='budget of the runs compared (default 10000: run_one.sh 5 rounds)')
    args = parser.parse_args()
    sources = {p.name: None for p in args.root.iterdir() if p.is_dir()} \
        if args.root.is_dir() else {}
    for folder in args.shipped:
        for p in sorted(folder.iterdir()):
            if (p / group_name(args.task, args.updates)).is_dir() and sources.get(p.name) is None:
                sources[p.name] = folder
    if args.variants:
        missing = sorted(set(args.variants) - set(sources))
        if missing:
            parser.error(f'no runs or shipped checkpoints of variant(s) {", ".join(missing)} '
                         f'for {args.task}; found: {", ".join(sorted(sources))}')
        sources = {v: sources[v] for v in args.variants}
    variants = sorted(sources, key=lambda v: (v != REFERENCE_VARIANT, v != 'paper', v))
    tables = {}
    for variant in variants:
        folder = evaluate_variant(args.root, variant, args.task, args.evals,
                                  splits=args.splits, episodes=args.episodes, jobs=args.jobs,
                                  updates=args.updates, shipped=sources[variant])
        if folder is not None:
            tables[variant] = folder
            if args.export:
                export_runs(args.root, variant, args.task, args.export, args.evals, args.updates,
                            overwrite=args.overwrite)
    missing = [v for v in args.against if v not in tables]
    if missing:
        parser.error(f'--against {" ".join(missing)}: no evaluated runs of that variant')
    paired_with = None
    if args.paired_with:
        variant, _, method = args.paired_with.partition(':')
        if variant not in tables or not method:
            parser.error(f'--paired-with {args.paired_with}: give VARIANT:METHOD of an evaluated '
                         f'variant ({", ".join(tables)})')
        paired_with = (variant, method)
    rows = variant_rows(tables, args.against, paired_with)
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / _task_folder(args.task, args.updates)
    walls = []
    for variant, folder in tables.items():
        runs = _with_train_seconds(per_run(folder),
                                   args.root / variant / _task_folder(args.task, args.updates))
        walls.append(f'**{variant}**\n\n{wall_time_table(runs)}')
    Path(f'{stem}_wall_times.md').write_text(
        'Seconds of training (`zeus loop`: collection + updates) + evaluation (all splits), '
        'two runs sharing the two cores:\n\n' + '\n\n'.join(walls) + '\n')
    write_csv(stem.with_suffix('.csv'), rows)
    stem.with_suffix('.md').write_text(markdown(rows, args.against, paired_with))
    plot(rows, stem.with_suffix('.png'),
         f'{args.task}, {args.updates:,} updates: configs and methods')
    print(markdown(rows, args.against, paired_with))
    print(f'wrote {stem}.csv, .md, .png and {stem.name}_wall_times.md')


if __name__ == '__main__':
    main()
