"""Build the model zoo (checkpoints/<family>/<method>.pt, cards, index) from the archive.

Reads checkpoints/zoo.yaml. Per family and method it ships the archive seed with the best mean
return on the train values (read from the archive cards, evaluation seed 100), gives every
checkpoint with a learned context its read-out (psi -> the context in physical units), its
novelty monitor and the train values' mean psi (what `frozen` runs freeze to), then measures
it afresh with evaluation seed 200 on values and initial states that chose nothing:
return on the train and the beyond-range values, and the value of adaptation (return with the
context live minus frozen at the train mean, paired per value and episode, mean ± s.e. over
values). Writes each card and the table between the markers of checkpoints/README.md.

    python scripts/build_zoo.py                 # every family (about 10 min on 2 cores)
    python scripts/build_zoo.py --family Cheetah-Bias-v0
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import hashlib
import os
from pathlib import Path
import re
import shutil
import sys

import yaml

from zeus_ros.offline.evaluation.adaptation import (
    EVAL_SEED,
    AdaptationReport,
    fmt,
    measure_adaptation,
)

ROOT = Path(__file__).resolve().parents[1]
CHECKPOINTS = ROOT / 'checkpoints'
MANIFEST = CHECKPOINTS / 'zoo.yaml'
INDEX = CHECKPOINTS / 'README.md'
EPISODES = 3
BEGIN, END = '<!-- zoo index: scripts/build_zoo.py -->', '<!-- end zoo index -->'


@dataclass
class Measured:
    """What the card and the index report for one zoo checkpoint."""

    family: str
    method: str
    path: Path
    source: Path
    seed: int
    train_returns: dict[int, float]
    report: AdaptationReport

    @property
    def returns(self) -> dict[str, tuple[float, float]]:
        """Mean return ± s.e. per split."""
        return self.report.returns

    @property
    def voa(self) -> dict[str, tuple[float, float]]:
        """Value of adaptation ± s.e. per split (empty without a context)."""
        return self.report.adaptation

    @property
    def sensitivity(self) -> float:
        """Mean |delta action| when psi of one extreme train value replaces the other's."""
        return self.report.sensitivity


def family_dir(task: str) -> str:
    """`Cheetah-Bias-v0` -> `cheetah_bias_v0`."""
    return task.lower().replace('-', '_')


def card_train_return(card: Path) -> float:
    """Mean return on the train values from an archive card's measured table."""
    match = re.search(r'^\| train \| (-?[0-9.]+) \|', card.read_text(), re.MULTILINE)
    if match is None:
        raise SystemExit(f'{card}: no "| train | <return> |" row; evaluate it first (zeus eval)')
    return float(match.group(1))


def choose_seed(prefix: Path) -> tuple[Path, dict[int, float]]:
    """The archive file `<prefix>_s<N>.pt` with the best train return, and every seed's."""
    seeds = {int(p.stem.rsplit('_s', 1)[1]): p for p in prefix.parent.glob(prefix.name + '_s*.pt')
             if p.stem.rsplit('_s', 1)[1].isdigit()}
    if not seeds:
        raise SystemExit(f'no archive checkpoints {prefix}_s*.pt')
    returns = {seed: card_train_return(path.with_suffix('.md')) for seed, path in seeds.items()}
    best = max(returns, key=lambda s: returns[s])
    return seeds[best], returns


def learned_context(path: Path) -> bool:
    """True when the checkpoint infers its context (psi), so it gets a read-out."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.learning.methods import method_objective

    return method_objective(InferenceAgent.from_checkpoint(path).method).context_source == 'psi'


def prepare(target: Path) -> None:
    """Give a learned-context checkpoint its read-out, novelty monitor and train-mean psi."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.learning.readout import store_readout, store_train_mean
    from zeus_ros.offline.evaluation.calibrate import calibrate_readout
    from zeus_ros.offline.evaluation.evaluate import train_mean_context

    agent = InferenceAgent.from_checkpoint(target)
    readout, novelty = calibrate_readout(agent, steps=2000, progress=True)
    print(f'  {readout.describe()}\n  {novelty.describe()}', flush=True)
    store_readout(target, readout, target, novelty)
    store_train_mean(target, train_mean_context(agent, episodes=EPISODES, seed=EVAL_SEED))


def sha256(path: Path) -> str:
    """Hex digest of a file."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def method_note(m: Measured) -> str:
    """Which training method the file holds, in words."""
    stored = m.report.method  # read when it was measured: the card may not match it yet
    if m.method == 'zeus':
        return f"the family's default, stored as `{stored}`"
    return {'no_context': 'plain SAC, no context', 'oracle': 'SAC given the true context'
            }.get(m.method, f'`{stored}`')


def write_card(m: Measured, budget: str) -> None:
    """The zoo card beside the checkpoint: provenance, choice, fresh measurements."""
    from sim_bridge.families import family

    fam = family(m.family)
    source_card = m.source.with_suffix('.md').read_text()
    provenance = source_card.split('Measured (', 1)[0].split('\n', 1)[1].strip()
    seeds = ', '.join(f's{s}: {r:.1f}' for s, r in sorted(m.train_returns.items()))
    lines = [
        f'# Zoo card: `{family_dir(m.family)}/{m.method}.pt`', '',
        f'{m.family}: {fam.varies}. `{m.method}` ({method_note(m)}), {budget}. Deployed by '
        f'`zeus launch --task {m.family}`' + (' (policy and estimator).' if m.method == 'zeus'
                                              else ' --method ' + m.method + '.'), '',
        '| field | value |', '|---|---|',
        f'| source (research archive) | `checkpoints/{m.source.relative_to(CHECKPOINTS)}` '
        f'(sha256 `{sha256(m.source)[:16]}...`) |',
        f'| why this seed | best mean return on the train values among the archive seeds '
        f'({seeds}; archive cards, evaluation seed 100) |',
        '| added here | ' + ('context read-out (psi -> the context in its units), novelty '
                            "monitor, the train values' mean psi (what frozen runs use)"
                            if m.voa else 'nothing (no learned context)') + ' |',
        f'| file | {m.path.stat().st_size / 1e6:.2f} MB, sha256 `{sha256(m.path)}` |', '',
        f'Measured by `python scripts/build_zoo.py --family {m.family}` (evaluation seed '
        f'{EVAL_SEED}: initial states that chose nothing; {EPISODES} deterministic episodes per '
        'value; mean ± s.e. over the values):', '',
        '| split | return | value of adaptation (live - frozen at the train mean) |',
        '|---|---|---|',
        *(f'| {split} | {fmt(m.returns[split])} | {fmt(m.voa.get(split))} |'
          for split in ('train', 'extrapolation')),
    ]
    if m.voa:
        lines += ['', f'Context sensitivity (mean |delta action| in [-1, 1] units when psi of one '
                  f"extreme train value replaces the other's): **{m.sensitivity:.3f}**."]
    lines += ['', '## The archive run it came from', '', provenance, '']
    m.path.with_suffix('.md').write_text('\n'.join(lines))


def index_table(rows: list[Measured], budgets: dict[str, str]) -> str:
    """One row per zoo checkpoint: what a user picks from."""
    from sim_bridge.families import family

    out = ['| family (what varies) | checkpoint | budget | return train | return beyond '
           'the range | value of adaptation beyond the range | sha256 |',
           '|---|---|---|---|---|---|---|']
    for m in rows:
        rel = f'{family_dir(m.family)}/{m.method}.pt'
        out.append(f'| {m.family} ({family(m.family).varies}) | [`{rel}`]({rel[:-3]}.md) | '
                   f'{budgets[m.family]} | {fmt(m.returns["train"])} | '
                   f'{fmt(m.returns["extrapolation"])} | {fmt(m.voa.get("extrapolation"))} | '
                   f'`{sha256(m.path)[:12]}` |')
    return '\n'.join(out)


def main(argv: list[str] | None = None) -> int:
    """Build the requested families; rewrite the index when every family was built."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--family', action='append', help='only these families (repeatable)')
    args = parser.parse_args(argv)
    manifest = yaml.safe_load(MANIFEST.read_text())['families']
    wanted = args.family or list(manifest)
    unknown = sorted(set(wanted) - set(manifest))
    if unknown:
        print(f'build_zoo: --family {unknown[0]}: not in {MANIFEST} ({", ".join(manifest)})',
              file=sys.stderr)
        return 2
    built: list[Measured] = []
    for name in manifest:
        entry = manifest[name]
        for method, prefix in entry['methods'].items():
            target = CHECKPOINTS / family_dir(name) / f'{method}.pt'
            if name not in wanted:
                continue
            source, train_returns = choose_seed(CHECKPOINTS / prefix)
            seed = int(source.stem.rsplit('_s', 1)[1])
            print(f'[zoo] {name} {method}: {source.relative_to(CHECKPOINTS)} (seed {seed})',
                  flush=True)
            target.parent.mkdir(parents=True, exist_ok=True)
            # Built under a name no card or index pins (the old ones would refuse the new
            # bytes: zeus_ros/integrity.py), then moved in place and recorded anew.
            staging = target.with_name(f'{method}.building.pt')
            shutil.copyfile(source, staging)
            if learned_context(staging):
                prepare(staging)
            report = measure_adaptation(staging, episodes=EPISODES)
            os.replace(staging, target)
            measured = Measured(name, method, target, source, seed, train_returns, report)
            write_card(measured, entry['budget'])
            built.append(measured)
            print(f'[zoo]   train {fmt(measured.returns["train"])}, beyond the range '
                  f'{fmt(measured.returns["extrapolation"])}, value of adaptation beyond '
                  f'{fmt(measured.voa.get("extrapolation"))}', flush=True)
    if set(wanted) == set(manifest):
        text = INDEX.read_text()
        budgets = {name: entry['budget'] for name, entry in manifest.items()}
        table = index_table(built, budgets)
        head, _, rest = text.partition(BEGIN)
        _, _, tail = rest.partition(END)
        INDEX.write_text(f'{head}{BEGIN}\n{table}\n{END}{tail}')
        print(f'[zoo] index: {INDEX}')
    elif built:  # the rebuilt files' sha256 in their rows: the index pins what it names
        text = INDEX.read_text()
        for m in built:
            rel = re.escape(f'{family_dir(m.family)}/{m.method}.pt')
            text = re.sub(rf'^(\|.*\[`{rel}`\].*\| `)[0-9a-f]{{12}}(` \|)$',
                          lambda match, m=m: f'{match.group(1)}{sha256(m.path)[:12]}'
                                             f'{match.group(2)}', text, flags=re.MULTILINE)
        INDEX.write_text(text)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
