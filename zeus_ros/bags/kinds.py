"""What a recording is: a manual recording, a collection, a continual split or the rehearsal.

Each bag folder says it in a small file beside metadata.yaml (LABEL_FILE), written where the
bag is opened: the recorder node (manual, or a `--continual` split), `zeus collect` / `zeus
loop` (collected) and the continual trainer's rehearsal. `zeus bags` lists them and `zeus
train --bags` chooses by kind: retraining "from what it recorded" must not silently take the
continual trainer's rehearsal along (issue 52). A bag without the file (older, or written by
`ros2 bag record`) is judged by its folder (continual_rehearsal/, continual_<date>/, the names
the launch gives them), else counts as manual. No ROS, no offline/.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
import time

import yaml

__all__ = ['DEFAULT_KINDS', 'KINDS', 'LABEL_FILE', 'UNLABELLED', 'BagLabel', 'bag_kind',
           'choose_bags', 'read_label', 'write_label']

LABEL_FILE = 'zeus_bag.yaml'
KINDS = ('manual', 'collected', 'continual', 'rehearsal')
"""manual: `zeus launch --record`; collected: `zeus collect` / `zeus loop`; continual: a split
of `zeus launch --continual`; rehearsal: the continual trainer's recording at the train values."""
DEFAULT_KINDS = ('manual', 'collected', 'continual')
"""What `zeus train --bags` takes unless told (--kinds): everything but the rehearsal."""
UNLABELLED = 'manual'
"""The kind of a bag that does not say (recorded before bags said it, or by ros2 bag record)."""
REHEARSAL_FOLDER = 'continual_rehearsal'
"""Where the continual trainer keeps its rehearsals (beside the recordings)."""
CONTINUAL_PREFIX = 'continual_'
"""How `zeus launch --continual` names its recording folder (continual_<date>)."""


@dataclass(frozen=True)
class BagLabel:
    """What a bag is and where it came from."""

    kind: str
    task: str = ''
    checkpoint: str = ''
    """The checkpoint deployed when the recording started ('' for a random policy)."""
    when: str = ''
    """Local time the bag was opened, ISO 8601 to the second."""


def write_label(bag: Path | str, label: BagLabel) -> None:
    """Write `label` into the bag folder (which exists); ValueError for an unknown kind."""
    if label.kind not in KINDS:
        raise ValueError(f'bag kind {label.kind!r}: choose one of {", ".join(KINDS)}')
    when = label.when or time.strftime('%Y-%m-%dT%H:%M:%S')
    text = yaml.safe_dump({**asdict(label), 'when': when}, sort_keys=False)
    (Path(bag) / LABEL_FILE).write_text(text, encoding='utf-8')


def read_label(bag: Path | str) -> BagLabel | None:
    """The bag's label, None when it has none (or an unreadable one: it then counts as manual)."""
    path = Path(bag) / LABEL_FILE
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None
    if not isinstance(data, dict) or data.get('kind') not in KINDS:
        return None
    return BagLabel(**{key: str(data.get(key) or '') for key in ('kind', 'task', 'checkpoint',
                                                                  'when')})


def bag_kind(bag: Path) -> tuple[str, bool]:
    """(kind, whether the bag says it): a bag without a label is judged by its folders."""
    label = read_label(bag) if bag.is_dir() else None
    if label is not None:
        return label.kind, True
    folders = bag.resolve().parts[:-1]
    if REHEARSAL_FOLDER in folders:
        return 'rehearsal', False
    if any(part.startswith(CONTINUAL_PREFIX) for part in folders):
        return 'continual', False
    return UNLABELLED, False


def choose_bags(bags: Sequence[Path], kinds: Sequence[str],
                log: Callable[[str], None]) -> list[Path]:
    """The bags of the chosen kinds; says once how many had no kind (taken as manual).

    ValueError naming the kinds found when none is left.
    """
    unknown = sorted(set(kinds) - set(KINDS))
    if unknown:
        raise ValueError(f'--kinds {",".join(unknown)}: choose from {", ".join(KINDS)}')
    chosen: list[Path] = []
    unlabelled, left_out = 0, dict[str, int]()
    for bag in bags:
        kind, said = bag_kind(bag)
        unlabelled += not said
        if kind in kinds:
            chosen.append(bag)
        else:
            left_out[kind] = left_out.get(kind, 0) + 1
    if unlabelled:
        log(f'{unlabelled} bag(s) say not what they are (recorded before bags said it, or by '
            f'ros2 bag record): judged by their folder ({REHEARSAL_FOLDER}/: rehearsal, '
            f'{CONTINUAL_PREFIX}*/: continual), else taken as {UNLABELLED}')
    if left_out:
        log('left out by kind: ' + ', '.join(f'{n} {kind}' for kind, n in left_out.items())
            + f' (--kinds {",".join(KINDS)} takes every bag)')
    if not chosen:
        raise ValueError(f'no bag of kind {", ".join(kinds)} among the {len(bags)} found '
                         '(zeus bags lists them; choose with --kinds)')
    return chosen
