"""`zeus report` of a continual run: return per context segment over time, each decision on it.

    zeus report bags/continual_<date>     # or bags/continual_<date>_continual

`zeus launch --continual` leaves two folders: the recording (bags/continual_<date>/, closed
rosbag2 splits) and beside it the trainer's (bags/continual_<date>_continual/history.jsonl, one
JSON line per event). Whether the deployment gets better where it runs, and which decision did
it, shows only with both on one time axis, so this reads the two together: the return of every
context segment (reward per step x the task's episode length, from the closed splits) and every
round start, gate decision (gain ± s.e.), swap, rollback, failure and stop of the history, placed
at the run time of the step recorded when it happened (the recorder's receive stamps). It writes
continual_segments.csv, continual_events.csv and continual_returns.png (default: into the
`_continual` folder) and a short summary. benchmarks/bench_continual.py draws its fixed vs
continual figures with the same functions (`segments`, `marks`, `plot_modes`).

No ROS; numpy, the bag reader and matplotlib are imported inside the functions, so that
`zeus report --help` stays fast.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    import numpy as np

    from zeus_ros.offline.data.ingest import Dataset

__all__ = [
    'HISTORY',
    'SUFFIX',
    'ContinualFolders',
    'ContinualReport',
    'ContinualReportError',
    'PlotRun',
    'StepClock',
    'build_report',
    'continual_folders',
    'event_rows',
    'marks',
    'plot_modes',
    'plot_returns',
    'segment_rows',
    'segments',
    'step_stamps',
    'write_continual_report',
]

SUFFIX = '_continual'
"""The trainer's folder is the recording's name + this (continual_node: `out` default)."""
HISTORY = 'history.jsonl'
MIN_SEGMENT_STEPS = 20
"""Segments with fewer rewarded steps are left out: a segment cut by the recording's start or
end holds a few steps, and its return would be one start-up transient."""
SMOOTH = 30
"""Segments in the running mean (one segment alone swings from -50 to -200 beyond the range);
a third of them in a shorter run."""
SEGMENT_COLUMNS = ('segment', 't_s', 'context', 'return')
"""What `segments` gives per segment (bench_continual's segments.csv columns)."""
EVENT_COLUMNS = ('t_s', 'time', 'event', 'round', 'decision', 'gain', 'se', 'required',
                 'checkpoint', 'reason', 'outside_s')
"""continual_events.csv: live_check rows put the live change in `gain` and minus its allowed
loss in `required`; a swap its gate gain. `outside_s`: how long before the first or after the
last recorded step the line was written (drawn at the run's start or end; 0: inside)."""
OUTSIDE_S = 60.0
"""History lines further than this outside the recorded steps are named in the summary (the
trainer starts before step 0, and the split being written is not read)."""
FILES = ('continual_segments.csv', 'continual_events.csv', 'continual_returns.png')


class ContinualReportError(ValueError):
    """No history, no closed split, unreadable bags: the message says which and where."""


# ------------------------------------------------------------------------------ folders
@dataclass(frozen=True)
class ContinualFolders:
    """A continual run's recording and its trainer folder (which holds history.jsonl)."""

    recording: Path
    trainer: Path

    @property
    def history(self) -> Path:
        """The trainer's history.jsonl."""
        return self.trainer / HISTORY


def continual_folders(folder: Path | str) -> ContinualFolders | None:
    """The recording and trainer folder that `folder` (either one) names; None: neither.

    A user passes whichever is at hand: the recording (its `_continual` sibling holds the
    history), the `_continual` folder, or a trainer folder set elsewhere by `out` (its start
    line names the recording). A folder of bag splits with no history is still a recording:
    the report then says the history is missing instead of looking for training runs.
    """
    folder = Path(folder).resolve()
    if (folder / HISTORY).is_file() and not folder.name.endswith(SUFFIX):
        recording = _recording_of(folder / HISTORY)
        if recording is not None:
            return ContinualFolders(recording, folder)
    if folder.name.endswith(SUFFIX) and len(folder.name) > len(SUFFIX):
        return ContinualFolders(folder.with_name(folder.name[:-len(SUFFIX)]), folder)
    trainer = folder.with_name(folder.name + SUFFIX)
    if (trainer / HISTORY).is_file() or _holds_splits(folder):
        return ContinualFolders(folder, trainer)
    return None


def _recording_of(history: Path) -> Path | None:
    from zeus_ros.system.continual_settings import read_history

    for event in read_history(history):
        if event.get('event') == 'start' and event.get('recording'):
            return Path(event['recording'])
    return None


def _holds_splits(folder: Path) -> bool:
    """True when a child of `folder` is a rosbag2 bag (the recorder's splits)."""
    if not folder.is_dir():
        return False
    return any((child / 'metadata.yaml').is_file() for child in folder.iterdir()
               if child.is_dir())


# ------------------------------------------------------------------------------ time axis
def _epoch_s(iso: str) -> float:
    """Seconds since the epoch of an ISO time (the history's are UTC; a naive one is too)."""
    when = datetime.datetime.fromisoformat(iso)
    if when.tzinfo is None:
        when = when.replace(tzinfo=datetime.UTC)
    return when.timestamp()


def step_stamps(splits: Sequence[Path]) -> list[tuple[float, int]]:
    """(time the step's state was recorded [s, epoch], step) of every recorded step.

    The bag time of a recorder's message is when it received it (time.time_ns()), the one
    clock the history shares: the header stamps are simulation time.
    """
    from rosbags.rosbag2 import Reader

    from zeus_ros.bags.recover import step_from_cdr
    from zeus_ros.bags.schema import TOPIC_STATE

    seen: dict[int, int] = {}
    for bag in splits:
        reader = Reader(bag)
        reader.open()
        try:
            wanted = [c for c in reader.connections if c.topic == TOPIC_STATE]
            for _connection, stamp, raw in reader.messages(connections=wanted):
                step = step_from_cdr(raw)
                if step is not None:
                    seen.setdefault(step, stamp)
        finally:
            reader.close()
    return [(stamp / 1e9, step) for step, stamp in seen.items()]


def _one_run(splits: Sequence[Path]) -> list[tuple[float, int]]:
    """step_stamps of splits that continue one another's steps (else ContinualReportError).

    The recorder starts every launch in a new, empty folder; splits whose steps start over
    are of two runs, and their segments and times would be mixed up.
    """
    stamps: list[tuple[float, int]] = []
    last: tuple[int, Path] | None = None
    for split in splits:
        mine = step_stamps([split])
        if not mine:
            continue
        low = min(step for _, step in mine)
        if last is not None and low <= last[0]:
            raise ContinualReportError(
                f'{split}: its steps start over (from {low}, after step {last[0]} in '
                f'{last[1].name}): the splits of two runs in one recording; report each run '
                'from a folder of its own splits')
        last = (max(step for _, step in mine), split)
        stamps += mine
    return stamps


@dataclass(frozen=True)
class StepClock:
    """Run time [s from the first step] of recorded steps and of wall-clock instants.

    With `rate` (control steps per second), a step's time is (step - first) / rate, as
    bench_continual measures; without it, when the step was recorded. An instant (a history
    line) takes the time of the step recorded nearest to it: a decision made before the first
    or after the last closed step is drawn at the run's start or end, never outside it.
    """

    steps: np.ndarray
    """Recorded step indices, ascending."""
    received_s: np.ndarray
    """When each was recorded [s, epoch], same order."""
    rate: float | None = None

    @classmethod
    def from_stamps(cls, stamps: Sequence[tuple[float, int]], rate: float | None = None
                    ) -> StepClock:
        """The clock of (received [s, epoch], step) pairs (`step_stamps`), any order."""
        import numpy as np

        ordered = sorted(stamps, key=lambda pair: pair[1])
        return cls(np.asarray([s for _, s in ordered], np.int64),
                   np.asarray([t for t, _ in ordered], np.float64), rate)

    def __len__(self) -> int:
        return int(self.steps.size)

    def of_steps(self, steps: Sequence[int] | np.ndarray) -> np.ndarray:
        """Run time of each step (one not recorded: that of the nearest recorded one)."""
        import numpy as np

        steps = np.asarray(steps, np.int64)
        if self.rate is not None:
            return (steps - self.steps[0]) / float(self.rate)
        where = np.clip(np.searchsorted(self.steps, steps), 0, len(self) - 1)
        return np.round(self.received_s[where] - self.received_s[0], 3)  # ms: epoch floats

    def of_epochs(self, epochs: Sequence[float]) -> np.ndarray:
        """Run time of each instant [s, epoch]: that of the step recorded nearest to it."""
        import numpy as np

        order = np.argsort(self.received_s, kind='stable')
        received = self.received_s[order]
        at = np.asarray(epochs, np.float64)
        right = np.clip(np.searchsorted(received, at), 0, len(self) - 1)
        left = np.clip(right - 1, 0, len(self) - 1)
        nearer = np.where(np.abs(received[left] - at) <= np.abs(received[right] - at),
                          left, right)
        return self.of_steps(self.steps[order][nearer])

    @property
    def duration_s(self) -> float:
        """Run time of the last recorded step."""
        return float(self.of_steps(self.steps[-1:])[0]) if len(self) else 0.0


# ------------------------------------------------------------------------------ segments
def _episode_length(task: str) -> int:
    from sim_bridge.registry import task_class

    return int(cast(Any, task_class(task)).episode_length)  # a class attribute of each task


def segment_rows(data: Dataset, time_of: Any) -> list[dict[str, Any]]:
    """Per context segment: start time, rewarded steps, context and return per episode.

    `time_of(steps)` gives run times (StepClock.of_steps). The return is the mean reward per
    step x the task's episode length: segments and episodes are not aligned (a segment ends
    mid-episode), and so a segment of any length reads as what one episode there earns.
    """
    import numpy as np

    episode = _episode_length(data.task)
    rewarded = [ep for ep in data.episodes if ep.reward.size]
    if not rewarded:
        return []
    segment = np.concatenate([ep.segment[1:] for ep in rewarded])
    step = np.concatenate([ep.steps[1:] for ep in rewarded])
    reward = np.concatenate([ep.reward for ep in rewarded])
    context = np.concatenate([ep.context[1:, :1] for ep in rewarded])[:, 0] \
        if data.context_names else np.full(segment.size, np.nan)
    keys, inverse, counts = np.unique(segment, return_inverse=True, return_counts=True)
    sums = np.bincount(inverse, weights=reward)
    starts = np.full(keys.size, np.iinfo(np.int64).max)
    np.minimum.at(starts, inverse, step)
    first = np.full(keys.size, segment.size)
    np.minimum.at(first, inverse, np.arange(segment.size))
    times = time_of(starts)
    return [{'segment': int(keys[i]), 't_s': float(times[i]), 'context': float(context[first[i]]),
             'return': float(sums[i] / counts[i] * episode), 'steps': int(counts[i]),
             'start_step': int(starts[i])}
            for i in range(keys.size) if counts[i] >= MIN_SEGMENT_STEPS]


def segments(splits: Sequence[Path], rate: float) -> list[dict[str, Any]]:
    """Return per segment (reward per step x the episode) with its start time in seconds.

    Time from the run's first step at `rate` steps per second (bench_continual's figures);
    the keys are SEGMENT_COLUMNS.
    """
    import numpy as np

    from zeus_ros.offline.data.ingest import ingest_bags

    data = ingest_bags(list(splits))
    start = min(int(ep.steps[0]) for ep in data.episodes)
    clock = StepClock(np.asarray([start], np.int64), np.zeros(1), rate)
    return [{key: row[key] for key in SEGMENT_COLUMNS}
            for row in segment_rows(data, clock.of_steps)]


# ------------------------------------------------------------------------------ events
def _matches(event: dict[str, Any], kind: str) -> bool:
    return bool(event.get('event') == kind or event.get('decision') == kind)


def marks(events: Sequence[dict[str, Any]], kind: str, lat: Sequence[tuple[float, Any, int]],
          rate: float) -> list[float]:
    """Run time [s, from step 0 at `rate`] of each event or decision `kind` (swap, refuse...).

    `lat`: (received [s, epoch], anything, step) per recorded step (bench_continual's
    latencies); an event takes the time of the step recorded nearest to it.
    """
    times = [_epoch_s(e['time']) for e in events if _matches(e, kind)]
    if not lat or not times:
        return []
    clock = StepClock.from_stamps([(t, k) for t, _, k in lat], rate)
    return [round(float(t), 1) for t in clock.of_epochs(times)]


def _number(value: Any) -> float | str:
    return float(value) if isinstance(value, int | float) else ''


def event_rows(history: Sequence[dict[str, Any]], clock: StepClock) -> list[dict[str, Any]]:
    """One row per history line, on the run's time axis (EVENT_COLUMNS).

    A gate line names no round: it belongs to the round started last.
    """
    timed = [e for e in history if isinstance(e.get('time'), str)]
    if not timed or not len(clock):
        return []
    epochs = [_epoch_s(e['time']) for e in timed]
    times = clock.of_epochs(epochs)
    first, last = float(clock.received_s.min()), float(clock.received_s.max())
    rows = []
    number: int | str = ''
    for event, t, epoch in zip(timed, times, epochs, strict=True):
        kind = str(event.get('event', ''))
        number = event.get('round', number) if kind != 'start' else ''
        row: dict[str, Any] = dict.fromkeys(EVENT_COLUMNS, '')
        row.update({'t_s': round(float(t), 2), 'time': event['time'], 'event': kind,
                    'round': number, 'outside_s': round(max(first - epoch, epoch - last, 0.0), 1)})
        if kind == 'gate':
            row.update({'decision': event.get('decision', ''), 'gain': _number(event.get('gain')),
                        'se': _number(event.get('se')),
                        'required': _number(event.get('required')),
                        'checkpoint': event.get('candidate', ''),
                        'reason': event.get('reason', '')})
        elif kind == 'swap':
            row.update({'decision': 'forced' if event.get('forced') else '',
                        'gain': _number(event.get('gate_gain')),
                        'checkpoint': event.get('checkpoint', '')})
        elif kind == 'live_check':
            allowed = event.get('allowed')
            row.update({'decision': event.get('decision', ''),
                        'gain': _number(event.get('live_change')),
                        'required': -float(allowed) if isinstance(allowed, int | float) else '',
                        'checkpoint': event.get('rolled_back_to') or event.get('checkpoint', ''),
                        'reason': event.get('error') or ''})
        elif kind == 'start':
            row['checkpoint'] = event.get('deployed', '')
            row['reason'] = 'resumed' if event.get('resumed') else ''
        elif kind == 'chain':  # where the next round starts: a refused candidate, or none
            row['checkpoint'] = event.get('resume_from') or ''
        elif kind == 'round':
            row['reason'] = event.get('trigger', '')
        elif kind in ('failure', 'swap_failed'):
            row['reason'] = event.get('reason', '')
        elif kind == 'stopped':
            progress = event.get('progress') or {}
            row['reason'] = f"stopped in {progress.get('phase', 'its start')}"
        rows.append(row)
    return rows


# ------------------------------------------------------------------------------ the report
@dataclass
class ContinualReport:
    """What `zeus report` found in a continual run: segments, events, counts."""

    folders: ContinualFolders
    task: str
    context_name: str
    episode_length: int
    splits: int
    steps: int
    duration_s: float
    segments: list[dict[str, Any]]
    events: list[dict[str, Any]]
    counts: dict[str, int] = field(default_factory=dict)

    def third(self, which: int) -> tuple[float, float, int]:
        """Mean return per segment, its s.e. and count over third `which` (0, 1, 2) of the run."""
        import numpy as np

        low, high = which * self.duration_s / 3, (which + 1) * self.duration_s / 3
        values = [s['return'] for s in self.segments
                  if low <= s['t_s'] < high or (which == 2 and s['t_s'] >= high)]
        if not values:
            return float('nan'), float('nan'), 0
        se = float(np.std(values, ddof=1) / np.sqrt(len(values))) if len(values) > 1 \
            else float('nan')
        return float(np.mean(values)), se, len(values)

    def summary(self) -> str:
        """A few lines: what ran, the decisions, and the return at the start and the end."""
        c = self.counts
        decided = [e['t_s'] for e in self.events if e['event'] == 'gate']
        lines = [f'{self.folders.recording}: {self.task}, {self.steps:,} steps in {self.splits} '
                 f'closed split(s) over {self.duration_s:.0f} s; {len(self.segments)} context '
                 f'segments (return per {self.episode_length}-step episode)',
                 f"rounds {c['rounds']}, gate decisions {c['deploys']} deploy / "
                 f"{c['refusals']} refuse, swaps {c['swaps']}, rollbacks {c['rollbacks']}, "
                 f"failures {c['failures']}, stopped {c['stopped']}"
                 + (f'; first gate decision at {min(decided):.0f} s' if decided else '')]
        for e in [e for e in self.events if e['event'] == 'gate'][-5:]:
            gain = f"{e['gain']:+.1f} ± {e['se']:.1f}" if e['gain'] != '' else '?'
            lines.append(f"  round {e['round']} at {e['t_s']:.0f} s: {e['decision']} "
                         f'(gain {gain} per episode, required {_fmt(e["required"])})')
        outside = sum(e['outside_s'] > OUTSIDE_S for e in self.events)
        if outside:
            lines.append(f'{outside} history line(s) written more than {OUTSIDE_S:.0f} s before '
                         'the first or after the last closed step: drawn at its start or end')
        for name, which in (('first', 0), ('last', 2)):
            mean, se, n = self.third(which)
            lines.append(f'return per segment, {name} third: {mean:.1f} ± {se:.1f} '
                         f'({n} segments)')
        return '\n'.join(lines)


def _fmt(value: float | str) -> str:
    return f'{value:.1f}' if isinstance(value, float) else '?'


def _counts(history: Sequence[dict[str, Any]]) -> dict[str, int]:
    def count(kind: str, decision: str | None = None) -> int:
        return sum(e.get('event') == kind and (decision is None or e.get('decision') == decision)
                   for e in history)

    return {'rounds': count('round'), 'deploys': count('gate', 'deploy'),
            'refusals': count('gate', 'refuse'), 'swaps': count('swap'),
            'rollbacks': count('live_check', 'rollback'),
            'failures': count('failure') + count('swap_failed'), 'stopped': count('stopped')}


def build_report(folder: Path | str) -> ContinualReport:
    """Read a continual run (its recording or `_continual` folder); raise ContinualReportError."""
    from zeus_ros.bags.errors import BagError
    from zeus_ros.bags.recording import closed_splits
    from zeus_ros.offline.data.ingest import ingest_bags
    from zeus_ros.system.continual_settings import read_history

    folders = continual_folders(folder)
    if folders is None:
        raise ContinualReportError(f'{folder}: not a continual run (no {HISTORY} in it or in '
                                   f'its {SUFFIX} sibling, no bag splits)')
    if not folders.history.is_file():
        raise ContinualReportError(f'{folder}: no continual history: {folders.history} does '
                                   'not exist (`zeus launch --continual` writes it beside the '
                                   'recording)')
    history = read_history(folders.history)
    splits = closed_splits(folders.recording)
    if not splits:
        raise ContinualReportError(f'{folders.recording}: no closed split with steps (a '
                                   'split is closed when the recorder starts the next one)')
    try:
        clock = StepClock.from_stamps(_one_run(splits))
        data = ingest_bags(splits)
    except (BagError, OSError) as error:
        raise ContinualReportError(f'{folders.recording}: {error}') from error
    if not len(clock) or not data.episodes:
        raise ContinualReportError(f'{folders.recording}: no step could be read')
    rows = segment_rows(data, clock.of_steps)
    events = event_rows(history, clock)
    _label_deployed(rows, events)
    return ContinualReport(folders, data.task, (data.context_names or ('context',))[0],
                           _episode_length(data.task), len(splits), len(clock),
                           clock.duration_s, rows, events, _counts(history))


def _label_deployed(rows: list[dict[str, Any]], events: list[dict[str, Any]]) -> None:
    """Name on each segment the checkpoint deployed when it started (start, swap, rollback)."""
    changes = [(e['t_s'], Path(e['checkpoint']).name) for e in events if e['checkpoint'] and (
        e['event'] in ('start', 'swap') or e['decision'] == 'rollback')]
    for row in rows:
        before = [name for t, name in changes if t <= row['t_s']]
        row['deployed'] = before[-1] if before else (changes[0][1] if changes else '')


def write_continual_report(folder: Path | str, out: Path | str | None = None,
                           title: str | None = None) -> ContinualReport:
    """build_report, then continual_segments.csv, continual_events.csv and the picture in `out`.

    `out` defaults to the trainer's folder, beside the history it reports.
    """
    import csv

    report = build_report(folder)
    out = Path(out) if out is not None else report.folders.trainer
    out.mkdir(parents=True, exist_ok=True)
    for name, rows, columns in (
            (FILES[0], report.segments, ('segment', 't_s', 'start_step', 'steps', 'context',
                                         'return', 'deployed')),
            (FILES[1], report.events, EVENT_COLUMNS)):
        with (out / name).open('w', newline='', encoding='utf8') as handle:
            writer = csv.DictWriter(handle, fieldnames=list(columns), extrasaction='ignore')
            writer.writeheader()
            writer.writerows(rows)
    ev = report.events
    run = PlotRun(
        'continual', [s['t_s'] for s in report.segments],
        [s['return'] for s in report.segments],
        swaps=[e['t_s'] for e in ev if e['event'] == 'swap'],
        rollbacks=[e['t_s'] for e in ev if e['decision'] == 'rollback'],
        refusals=[e['t_s'] for e in ev if e['event'] == 'gate' and e['decision'] == 'refuse'],
        failures=[e['t_s'] for e in ev if e['event'] in ('failure', 'swap_failed', 'stopped')],
        rounds=[e['t_s'] for e in ev if e['event'] == 'round'],
        gates=[(e['t_s'], float(e['gain']), float(e['se'] or 0.0), str(e['decision']))
               for e in ev if e['event'] == 'gate' and e['gain'] != ''])
    plot_returns(out / FILES[2], [run], title or (
        f'{report.task}: continual deployment, {report.folders.recording.name}'),
        f'return per segment (per {report.episode_length} steps)')
    return report


# ------------------------------------------------------------------------------ picture
@dataclass
class PlotRun:
    """One run's returns per segment and its marks [s], for `plot_returns`."""

    label: str
    t_s: list[float]
    returns: list[float]
    swaps: list[float] = field(default_factory=list)
    rollbacks: list[float] = field(default_factory=list)
    refusals: list[float] = field(default_factory=list)
    failures: list[float] = field(default_factory=list)
    """Failed rounds, failed swaps and stops."""
    rounds: list[float] = field(default_factory=list)
    gates: list[tuple[float, float, float, str]] = field(default_factory=list)
    """(t, gain, s.e., decision) of each gate: written at the top, green when deployed."""


def plot_returns(path: Path, runs: Sequence[PlotRun], title: str, ylabel: str) -> None:
    """Returns per segment as dots and a running mean; swap dashed, rollback dotted, refusal thin.

    Round starts are ticks at the bottom, failures and stops red dash-dot lines, each gate's
    gain ± s.e. is written at its time.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(9, 4))
    top = ax.get_xaxis_transform()  # x in data, y in axes fractions
    for index, run in enumerate(runs):
        color = f'C{index}'
        returns = np.asarray(run.returns, np.float64)
        ax.plot(run.t_s, returns, '.', color=color, alpha=0.25, markersize=3)
        width = min(SMOOTH, max(1, len(returns) // 3))  # a short run still shows a line
        if len(returns):
            smooth = np.convolve(returns, np.ones(width) / width, mode='valid')
            ax.plot(run.t_s[width - 1:], smooth, '-', color=color,
                    label=f'{run.label} (mean of the last {width} segments)')
        for t in run.refusals:
            ax.axvline(t, color=color, linestyle='-', linewidth=0.6, alpha=0.4)
        for t in run.swaps:
            ax.axvline(t, color=color, linestyle='--', linewidth=1)
        for t in run.rollbacks:
            ax.axvline(t, color=color, linestyle=':', linewidth=1.5)
        for t in run.failures:
            ax.axvline(t, color='red', linestyle='-.', linewidth=0.8, alpha=0.6)
        for t in run.rounds:
            ax.plot([t, t], [0.0, 0.04], color=color, linewidth=1, transform=top)
        for t, gain, se, decision in run.gates:
            ax.text(t, 0.98, f'{gain:+.1f}±{se:.1f}', transform=top, rotation=90, fontsize=6,
                    ha='right', va='top', color='green' if decision == 'deploy' else 'gray')
    ax.plot([], [], 'k--', linewidth=1, label='swap')
    ax.plot([], [], 'k:', linewidth=1.5, label='rollback')
    ax.plot([], [], 'k-', linewidth=0.6, alpha=0.4, label='refused candidate')
    if any(run.rounds for run in runs):
        ax.plot([], [], '|', color='k', markersize=8, label='round start')
    if any(run.failures for run in runs):
        ax.plot([], [], 'r-.', linewidth=0.8, alpha=0.6, label='failed round / stop')
    ax.set_xlabel('time [s]')
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=7 if any(run.gates for run in runs) else None)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_modes(path: Path, rows: Sequence[dict[str, Any]], summary: Sequence[dict[str, Any]],
               title: str, ylabel: str) -> None:
    """bench_continual's picture: fixed and continual side by side, in one place with ours.

    `rows`: segments with a `mode`; each mode's marks from its `summary` entry (`swap_s`,
    `rollback_s`, `refusal_s`).
    """
    runs = []
    for mode in dict.fromkeys(r['mode'] for r in rows):
        mine = [r for r in rows if r['mode'] == mode]
        info = next(i for i in summary if i['mode'] == mode)
        runs.append(PlotRun(mode, [r['t_s'] for r in mine], [r['return'] for r in mine],
                            swaps=list(info.get('swap_s', [])),
                            rollbacks=list(info.get('rollback_s', [])),
                            refusals=list(info.get('refusal_s', []))))
    plot_returns(path, runs, title, ylabel)
