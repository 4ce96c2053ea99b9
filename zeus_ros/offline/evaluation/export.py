"""`zeus export`: a trained checkpoint -> a small deployment checkpoint plus its card.

    zeus export --checkpoint runs/exp/walker_walk_v0/zeus_s0/run/final.pt \
        --out checkpoints/comparison/walker_walk_v0/zeus_s0.pt

The export keeps what acting needs (phi, psi, actor: checkpoint.DEPLOY_MODULES), ~10x smaller
than a training checkpoint; `zeus eval` gives it the same numbers. The card (<out>.md) says what
it is, how it was made (data, command, seed, commit) and what it scored: the evaluations of this
very checkpoint that `zeus eval` wrote below its folder (eval_<split>/ by default; each names
its checkpoint in eval.json), or those in --evals.
"""

from __future__ import annotations

import csv
import hashlib
from pathlib import Path
import sys
from typing import Any

from sim_bridge.presets import SPLITS

__all__ = ['card_text', 'export', 'find_evaluations']


def _fmt(value: str | None, digits: int = 1) -> str:
    if value in (None, '') or str(value).lower() == 'nan':
        return '-'
    return f'{float(value):.{digits}f}'


def _legacy_summaries(evals: Path) -> dict[str, Path]:
    """eval_<split>/summary.csv in `evals`, as runs from before eval.json hold them."""
    found = {split: evals / f'eval_{split}' / 'summary.csv' for split in SPLITS}
    return {split: path for split, path in found.items() if path.is_file()}


def find_evaluations(checkpoint: Path, evals: Path | None = None) -> dict[str, Path]:
    """Split -> summary.csv of the evaluations of `checkpoint`, for its card.

    Without `evals`: those whose eval.json names this very checkpoint (by sha256), in any
    folder below the checkpoint's (`zeus eval` writes eval_<split>/ there by default; any
    --out below it counts too) or in the sweep's trial folder above it (<trial>/run/final.pt,
    <trial>/eval_<split>/, also without eval.json as older trials left them). Evaluations of a
    checkpoint retrained since do not count. With `evals`: this checkpoint's below it, else
    what it holds (eval_<split>/summary.csv, or summary.csv of one evaluation), as given.
    """
    from zeus_ros.offline.evaluation.records import checkpoint_sha256, find_records, read_record

    sha = checkpoint_sha256(checkpoint)
    if evals is not None:
        records, older = find_records(evals, sha), _legacy_summaries(evals)
        if (evals / 'summary.csv').is_file():
            older[_split_of(evals / 'summary.csv')] = evals / 'summary.csv'
    else:
        trial = checkpoint.parent.parent
        records = find_records(checkpoint.parent, sha) + [
            record for folder in sorted(trial.glob('eval_*'))
            if (record := read_record(folder)) is not None and record.checkpoint_sha256 == sha]
        older = {split: path for split, path in _legacy_summaries(trial).items()
                 if not (path.parent / 'eval.json').is_file()}  # with one: judged by its sha
    found: dict[str, Path] = {}
    for record in sorted(records, key=lambda r: r.written_ns, reverse=True):
        found.setdefault(record.split, record.summary)
    for split, path in older.items():
        found.setdefault(split, path)
    return {split: found[split] for split in sorted(found, key=_split_rank)}


def _split_rank(split: str) -> tuple[int, str]:
    return (SPLITS.index(split) if split in SPLITS else len(SPLITS), split)


def _split_of(summary: Path) -> str:
    with summary.open(newline='') as handle:
        return next(csv.DictReader(handle), {}).get('split') or summary.parent.name


def _eval_rows(summaries: dict[str, Path]) -> list[tuple[str, dict[str, str], dict[str, str]]]:
    """(split, agent row, random row) of every evaluation summary found."""
    rows = []
    for split, path in summaries.items():
        with path.open(newline='') as handle:
            by_policy = {row['policy']: row for row in csv.DictReader(handle)}
        if 'agent' in by_policy:
            rows.append((split, by_policy['agent'], by_policy.get('random', {})))
    return rows


CARD_OPTIONS = ('context_norm', 'context_loss', 'critic_context_grad', 'context_target_tau',
                'context_consistency', 'context_head', 'model_horizon', 'model_target',
                'dynamics_loss', 'cadm_beta', 'up_osi_warmup_fraction', 'context_noise')
"""The method-specific options a card lists, in this order, where the method reads them."""
EVERY_METHOD_OPTIONS = ('exploration', 'representation_frozen_from')
"""Options of the card's options row that every method reads."""


def _option(config: Any, name: str) -> str:
    """`name value`, names and flags in code style."""
    value = getattr(config, name)
    return f'{name} `{value}`' if isinstance(value, str | bool) else f'{name} {value}'


def _method_cell(loaded: Any) -> str:
    """The method with the options that shape its context (only those its objective reads)."""
    config, objective = loaded.config, loaded.agent.objective
    cell = f'`{config.method}`'
    if objective.reads('alpha_psi'):
        cell += f' (alpha_psi = {config.alpha_psi})'
    if objective.reads('k'):
        cell += f', k = {config.k}'
    if objective.reads('aggregation'):
        cell += f', `{config.aggregation}` aggregation'
    return cell + f', context dim {loaded.agent.context_dim}'


def _options_cell(loaded: Any) -> str:
    """The card's options row: those the method reads, then those every method reads."""
    config, objective = loaded.config, loaded.agent.objective
    names = [name for name in CARD_OPTIONS if objective.reads(name)]
    return ', '.join(_option(config, name) for name in (*names, *EVERY_METHOD_OPTIONS))


def _networks_cell(loaded: Any) -> str:
    """Network widths: T/R and psi only for a method that has them."""
    config, objective = loaded.config, loaded.agent.objective
    parts = [f'{config.hidden_dim}-wide actor/critic']
    if objective.reads('model_hidden_dim'):
        parts.append(f'{config.model_hidden_dim}-wide {"/".join(_model_letters(objective))}')
    if objective.reads('context_hidden_dim'):
        parts.append(f'{config.context_hidden_dim}-wide psi')
    return ', '.join([*parts, f'feature dim {config.feature_dim}'])


def _model_letters(objective: Any) -> list[str]:
    """T, R, B for the transition, reward and backward models the method trains."""
    letters = {'transition': 'T', 'reward': 'R', 'backward': 'B'}
    return [letters[name] for name in objective.models]


def card_text(pt: Path, loaded: Any, *, summaries: dict[str, Path], command: str | None,
              commit: str | None, source: Path | None = None) -> str:
    """The markdown card of an exported checkpoint; `summaries`: split -> eval summary.csv."""
    from sim_bridge.families import load_preset

    config, spec, extra = loaded.config, loaded.spec, loaded.extra
    train_values = ', '.join(f'{v:g}' for value in load_preset(spec.task, 'train')
                             for v in value.values())
    obs = ('proprioceptive state' if spec.obs_kind == 'state' else 'pixels') + \
        f' {tuple(spec.obs_shape)}'
    bags = extra.get('bags', [])
    command = extra.get('command') or command or 'not recorded'
    commit = extra.get('code_commit') or commit or 'not recorded'
    digest = hashlib.sha256(pt.read_bytes()).hexdigest()
    lines = [
        f'# Card: `{pt.name}`', '',
        'A deployment export (`zeus export`): encoder, context encoder and actor only; '
        'it acts and infers the context exactly like the training checkpoint it came from, '
        'and cannot resume training.', '',
        '| field | value |', '|---|---|',
        f'| task | {spec.task} (context: {", ".join(spec.context_names)}; train values '
        f'{train_values}) |',
        f'| method | {_method_cell(loaded)} |',
        f'| method options | {_options_cell(loaded)} |',
        f'| observations | {obs} |',
        f'| networks | {_networks_cell(loaded)} |',
        f'| data | {extra.get("transitions", "?")} transitions from {len(bags)} bag(s) |',
        f'| updates | {loaded.step:,}, batch {config.batch_size} |',
        f'| seed | {config.seed} |',
        f'| command | `{command}` |',
        f'| code commit | `{commit}` |',
        f'| file | {pt.stat().st_size / 1e6:.2f} MB, sha256 `{digest}` |',
    ]
    if 'context_readout' in extra:
        from zeus_ros.learning.readout import ContextReadout

        readout = ContextReadout.from_dict(extra['context_readout']).describe()
        readout = readout.removeprefix('context read-out (').removesuffix(')')
        lines.insert(-1, f'| context read-out | {readout} |')
    if 'context_novelty' in extra:
        from zeus_ros.learning.readout import NoveltyMonitor

        novelty = NoveltyMonitor.from_dict(extra['context_novelty']).describe()
        novelty = novelty.removeprefix('context novelty monitor (').split('; fitted on')[0]
        lines.insert(-1, f'| context novelty monitor | {novelty} |')
    rows = _eval_rows(summaries)
    if rows:
        episodes = rows[0][1].get('episodes') or 1
        lines += ['', f'Measured (`zeus eval`, {_fmt(episodes, 0)} deterministic episode(s) per '
                  'context value, evaluation seed 100; the switching episode changes the context '
                  'unannounced; uniform random policy for scale; context sensitivity and value '
                  'of adaptation as in docs/results.md):', '',
                  '| split | return | random | switching episode | adaptation latency (steps) '
                  '| Spearman | context sensitivity | value of adaptation (frozen to mean) |',
                  '|---|---|---|---|---|---|---|---|']
        for split, agent, random in rows:
            lines.append(f'| {split} | {_fmt(agent["mean_return"])} | '
                         f'{_fmt(random.get("mean_return"))} | '
                         f'{_fmt(agent.get("switching_return"))} | '
                         f'{_fmt(agent.get("mean_latency"))} | '
                         f'{_fmt(agent.get("spearman"), 2)} | '
                         f'{_fmt(agent.get("sensitivity"), 3)} | '
                         f'{_fmt(agent.get("adaptation_value_mean"))} |')
    else:
        trained = source or pt
        lines += ['', f'Not evaluated yet: `zeus eval --checkpoint {trained} --split SPLIT` '
                  f'(results in {trained.parent}/eval_SPLIT/), then export again.']
    return '\n'.join(lines) + '\n'


def export(checkpoint: Path, out: Path, *, evals: Path | None = None,
           command: str | None = None, commit: str | None = None,
           readout_steps: int = 0, summaries: dict[str, Path] | None = None
           ) -> tuple[Path, Path]:
    """Write the deployment checkpoint and its card; returns (pt, md).

    The card's returns: `summaries` (split -> summary.csv), else find_evaluations in `evals`
    (none without).

    `readout_steps` > 0 calibrates the context read-out (readout.py) on that many steps of
    the policy on the train contexts and stores it in the export (state agents with a learned
    psi; pixel agents would render every step).
    """
    from zeus_ros.learning.checkpoint import export_for_deployment, load_checkpoint
    from zeus_ros.learning.readout import store_readout
    from zeus_ros.offline.evaluation.calibrate import deployment_readout

    if summaries is None:
        summaries = {} if evals is None else find_evaluations(checkpoint, evals)
    export_for_deployment(checkpoint, out)
    loaded = load_checkpoint(out, verify=False)  # just written; its old card is rewritten below
    try:
        fitted = deployment_readout(loaded.agent, readout_steps)
    except ValueError as error:  # the export is still valid without them
        print(f'zeus export: warning: no context read-out stored ({error}); raise '
              '--readout-steps', file=sys.stderr)
    else:
        if fitted is not None:
            store_readout(out, fitted[0], novelty=fitted[1])
            loaded = load_checkpoint(out, verify=False)
    card = out.with_suffix('.md')
    card.write_text(card_text(out, loaded, summaries=summaries, command=command, commit=commit,
                              source=checkpoint))
    return out, card
