"""Issue 10: how the comparison moves with the update budget (10k -> 20k -> ...), paired by seed.

    python experiments/budget_curves.py --task Cheetah-Run-v1 --updates 10000 20000 \
        [--runs default:no_context default:oracle k10:zeus] [--evals out/i10] \
        [--out docs/results/issue10]

Reads the evaluations compare_variants.py wrote (out/i10/<variant>/<task>_<N>k/) and writes
<task>_budget.csv/.md/.png, on the seeds every budget has: per budget, split and run: return
(mean ± s.e. over seeds), the gain
over no_context of the same budget (paired by seed), the value of adaptation (psi frozen at its
mean), and the change from the smallest budget on the same seeds (a run continued to a larger
budget is the same run trained longer, so that change is paired too).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from zeus_ros.offline.evaluation.eval_batch import group_name
from zeus_ros.offline.evaluation.metrics import overlap_style, write_csv
from zeus_ros.offline.evaluation.report import (
    REFERENCE,
    SPLIT_ORDER,
    mean_se,
    paired_difference,
    per_run,
)

REFERENCE_VARIANT = 'default'
"""The variant whose no_context runs define the gain (as in compare_variants.py)."""


def _label(variant: str, method: str) -> str:
    return f'{method} ({variant})'


def load_runs(evals: Path, task: str, budgets: list[int],
              runs: list[tuple[str, str]]) -> dict[int, list[dict[str, Any]]]:
    """Per budget: the per-seed rows of every (variant, method), method renamed to its label.

    Only the seeds that every budget has are kept (per run), so each line and each row joins
    the same runs trained longer.
    """
    out: dict[int, list[dict[str, Any]]] = {}
    for budget in budgets:
        rows = []
        for variant, method in runs:
            folder = evals / variant / group_name(task, budget)
            if folder.is_dir():
                rows += [{**r, 'method': _label(variant, method)} for r in per_run(folder)
                         if r['method'] == method]
        out[budget] = rows
    # only the seeds every budget has, so that a line joins the same runs trained longer
    for variant, method in runs:
        label = _label(variant, method)
        seeds = set.intersection(*({r['seed'] for r in rows if r['method'] == label}
                                   for rows in out.values()))
        for budget, rows in out.items():
            out[budget] = [r for r in rows if r['method'] != label or r['seed'] in seeds]
    return out


def _pm(value: tuple[float, float] | tuple[float, float, int] | None) -> str:
    return '-' if value is None else f'{value[0]:.1f} ± {value[1]:.1f}'


def budget_rows(by_budget: dict[int, list[dict[str, Any]]],
                runs: list[tuple[str, str]]) -> list[dict[str, Any]]:
    """One row per (budget, split, run) with the numbers of the budget table."""
    first = min(by_budget)
    reference = _label(REFERENCE_VARIANT, REFERENCE)
    rows = []
    for budget, mine in sorted(by_budget.items()):
        for split in SPLIT_ORDER:
            for variant, method in runs:
                label = _label(variant, method)
                cells = [r for r in mine if r['method'] == label and r['split'] == split]
                if not cells:
                    continue
                returns = [float(r['mean_return']) for r in cells]
                frozen = [float(r['adaptation_value_mean']) for r in cells
                          if r.get('adaptation_value_mean') not in ('', None)]
                gain = None if label == reference else paired_difference(
                    mine, label, reference, split)
                change = None
                if budget != first:
                    earlier = [{**r, 'method': 'earlier'} for r in by_budget[first]
                               if r['method'] == label]
                    change = paired_difference([*cells, *earlier], label, 'earlier', split)
                mean, se = mean_se(returns)
                rows.append({
                    'updates': budget, 'split': split, 'variant': variant, 'method': method,
                    'seeds': len(cells), 'return': mean, 'return_se': se,
                    'gain': '' if gain is None else gain[0],
                    'gain_se': '' if gain is None else gain[1],
                    'adaptation_mean': mean_se(frozen)[0] if frozen else '',
                    'adaptation_mean_se': mean_se(frozen)[1] if len(frozen) > 1 else '',
                    'change_from_first': '' if change is None else change[0],
                    'change_from_first_se': '' if change is None else change[1],
                    'text_gain': _pm(gain), 'text_change': _pm(change),
                    'text_adaptation': _pm(mean_se(frozen)) if len(frozen) > 1 else '-'})
    return rows


def markdown(rows: list[dict[str, Any]], first: int) -> str:
    """One table per split."""
    out = []
    for split in SPLIT_ORDER:
        mine = [r for r in rows if r['split'] == split]
        if not mine:
            continue
        out += [f'#### {split}', '',
                '| updates | method (config) | seeds | return | gain over no_context (paired) '
                f'| value of adaptation (mean) | change since {first:,} updates (paired) |',
                '|---|---|---|---|---|---|---|']
        out += [f"| {r['updates']:,} | {r['method']} ({r['variant']}) | {r['seeds']} | "
                f"{r['return']:.1f} ± {r['return_se']:.1f} | {r['text_gain']} | "
                f"{r['text_adaptation']} | {r['text_change']} |" for r in mine]
        out.append('')
    return '\n'.join(out)


def plot(rows: list[dict[str, Any]], path: Path, title: str) -> None:
    """Return and paired gain over no_context against the budget, one column per split."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    splits = [s for s in SPLIT_ORDER if any(r['split'] == s for r in rows)]
    labels = list(dict.fromkeys((r['variant'], r['method']) for r in rows))
    fig, axes = plt.subplots(2, len(splits), figsize=(4.4 * len(splits), 6.4), squeeze=False,
                             sharex=True)
    for col, split in enumerate(splits):
        for i, (variant, method) in enumerate(labels):
            mine = [r for r in rows if r['split'] == split and r['variant'] == variant
                    and r['method'] == method]
            if not mine:
                continue
            style = {**overlap_style(i, len(labels)), 'color': f'C{i}'}
            x = [r['updates'] for r in mine]
            axes[0][col].errorbar(x, [r['return'] for r in mine],
                                  yerr=[r['return_se'] for r in mine], capsize=3,
                                  label=_label(variant, method), **style)
            gains = [r for r in mine if r['gain'] != '']
            if gains:
                axes[1][col].errorbar([r['updates'] for r in gains], [r['gain'] for r in gains],
                                      yerr=[r['gain_se'] for r in gains], capsize=3, **style)
        axes[0][col].set_title(split, fontsize=10)
        axes[1][col].axhline(0.0, color='grey', lw=0.8)
        axes[1][col].set_xlabel('updates')
        for ax in axes[:, col]:
            ax.grid(alpha=0.3)
            ax.set_xticks(sorted({r['updates'] for r in rows}))
    axes[0][0].set_ylabel('episode return\n(mean ± s.e. over seeds)')
    axes[1][0].set_ylabel(f'gain over {REFERENCE}\n(paired by seed)')
    handles, names = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, names, loc='upper center', ncol=len(names), fontsize=8,
               bbox_to_anchor=(0.5, 1.0))
    fig.suptitle(title, fontsize=11, y=1.05)
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches='tight')
    plt.close(fig)


def _run_spec(text: str) -> tuple[str, str]:
    variant, sep, method = text.partition(':')
    if not sep or not variant or not method:
        raise argparse.ArgumentTypeError(f'{text!r}: expected VARIANT:METHOD, e.g. k10:zeus')
    return variant, method


def main() -> None:
    """Write the budget table and plot of one task."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--task', required=True)
    parser.add_argument('--updates', type=int, nargs='+', default=[10_000, 20_000])
    parser.add_argument('--runs', type=_run_spec, nargs='+',
                        default=[('default', 'no_context'), ('default', 'oracle'),
                                 ('k10', 'zeus')], help='VARIANT:METHOD ...')
    parser.add_argument('--evals', type=Path, default=Path('out/i10'))
    parser.add_argument('--out', type=Path, default=Path('docs/results/issue10'))
    args = parser.parse_args()
    by_budget = load_runs(args.evals, args.task, sorted(args.updates), args.runs)
    missing = [b for b, rows in by_budget.items() if not rows]
    if missing:
        parser.error(f'no evaluations for {args.task} at {missing} updates under {args.evals} '
                     '(run experiments/compare_variants.py --updates N first)')
    rows = budget_rows(by_budget, args.runs)
    stem = args.out / f"{args.task.lower().replace('-', '_')}_budget"
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(stem.with_suffix('.csv'), [{k: v for k, v in r.items()
                                         if not k.startswith('text_')} for r in rows])
    table = markdown(rows, min(by_budget))
    stem.with_suffix('.md').write_text(table)
    plot(rows, stem.with_suffix('.png'), f'{args.task}: return against the update budget')
    print(table)
    print(f'wrote {stem}.csv, .md, .png')


if __name__ == '__main__':
    main()
