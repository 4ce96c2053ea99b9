"""A recording on disk: which folders are bags, which splits are closed, how many steps each holds.

`find_bags` is the one place that decides what a bag is (ingest, training, `zeus recover`, the
continual trainer); `closed_splits` and `split_steps` are what continual deployment reads of a
recording that is still growing: the complete splits, never the one being written, and their
step counts from metadata.yaml (no message is read). No ROS, no offline/: the live continual
trainer (nodes/continual_node.py) and the training library both use it.
"""

from __future__ import annotations

from collections.abc import Sequence
import os
from pathlib import Path
from typing import Any

from zeus_ros.bags.errors import BagError
from zeus_ros.bags.schema import TOPIC_STEP

__all__ = ['BAG_FILES', 'CLOSED_STATES', 'bag_metadata', 'closed_splits', 'find_bags',
           'split_steps']

BAG_FILES = ('.mcap', '.db3')
"""Storage files of rosbag2 bags (mcap, sqlite3)."""
WHAT_BAGS_ARE = 'rosbag2 bags: folders with metadata.yaml, or .mcap / .db3 files'


def find_bags(paths: Path | str | Sequence[Path | str]) -> list[Path]:
    """Every bag at or below each path: a bag folder, a .mcap/.db3 file, or any folder of bags.

    Folders are searched at any depth (hidden ones skipped), because `zeus launch --record`
    writes bags/zeus_<date>/zeus_<date>_000/ and a user passes `bags`; a bag folder is taken
    whole, never searched further. The one place that decides what a bag is (ingest, train,
    recover).
    """
    items = [paths] if isinstance(paths, str | Path) else list(paths)
    found: list[Path] = []
    for item in map(Path, items):
        if not item.exists():
            raise BagError(item, f'no such file or directory (looked in {Path.cwd()})')
        if item.is_file():
            if item.suffix not in BAG_FILES:
                raise BagError(item, 'not a bag: expected a .mcap or .db3 file or a bag directory')
            found.append(item)
            continue
        below = _bags_below(item)
        if not below:
            raise BagError(item, f'no bags found: searched {item.resolve()} and every folder '
                                 f'below it for {WHAT_BAGS_ARE}')
        found.extend(below)
    return found


def _is_bag(folder: Path) -> bool:
    return (folder / 'metadata.yaml').exists() or _holds_storage(folder)


def _bags_below(folder: Path) -> list[Path]:
    """`folder` if it is a bag, else the bags in its subfolders at any depth, sorted."""
    if _is_bag(folder):
        return [folder]
    bags: list[Path] = []
    for root, dirs, _files in os.walk(folder):
        dirs.sort()
        keep = []
        for name in dirs:
            child = Path(root) / name
            if name.startswith('.'):
                continue
            if _is_bag(child):
                bags.append(child)
            else:
                keep.append(name)
        dirs[:] = keep  # a bag is taken whole; other folders are searched further
    return sorted(bags)


def _holds_storage(folder: Path) -> bool:
    return any(f.suffix in BAG_FILES for f in folder.iterdir() if f.is_file())


CLOSED_STATES = ('closed', 'recovered', None)
"""A split in one of these states is complete. None: metadata without a zeus state, written by
a writer that writes it only at close (`zeus collect`, `ros2 bag record`); 'provisional' (the
recorder's bag being written) and 'unfinished' (no metadata) may still grow."""


def bag_metadata(bag: Path) -> dict[str, Any]:
    """The rosbag2_bagfile_information of a bag folder's metadata.yaml ({} when it has none)."""
    import yaml

    try:
        return _metadata(bag)
    except (OSError, ValueError, AttributeError, yaml.YAMLError):
        return {}


def _metadata(bag: Path) -> dict[str, Any]:
    import yaml

    text = (bag / 'metadata.yaml').read_text('utf8')
    return (yaml.safe_load(text) or {}).get('rosbag2_bagfile_information') or {}


def closed_splits(recording: Path | str) -> list[Path]:
    """The complete bags under `recording` that hold steps, oldest first.

    Never the one being written; a split opened before step 0 may hold no step (skipped).
    """
    from zeus_ros.bags.recover import bag_state

    recording = Path(recording)
    if not recording.exists():
        return []
    try:
        bags = find_bags(recording)
    except BagError:  # nothing recorded yet
        return []
    return [bag for bag in bags if bag.is_dir() and bag_state(bag) in CLOSED_STATES
            and split_steps(bag) > 0]


def split_steps(bag: Path) -> int:
    """Steps in a closed split, from its metadata (no message is read)."""
    try:
        topics = _metadata(bag).get('topics_with_message_count') or []
    except (OSError, ValueError):
        return 0
    return sum(int(t.get('message_count', 0)) for t in topics
               if (t.get('topic_metadata') or {}).get('name') == TOPIC_STEP)
