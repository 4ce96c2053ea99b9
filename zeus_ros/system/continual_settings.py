"""Continual deployment, what the live trainer and the training round share: settings, history.

`ContinualSettings` is what one round does (the continual_trainer node's parameters of the
same names take their defaults from it); `append_history` / `read_history` write and read
OUT/history.jsonl, one JSON line per decision. The node (zeus_ros/nodes/continual_node.py)
imports these and never the training library: it runs each round in a child process
(`zeus continual-round`, zeus_ros/cli/continual_round.py over
zeus_ros/offline/training/continual.py), which imports them too. No ROS, no torch.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field, fields
import datetime
import inspect
import itertools
import json
import os
from pathlib import Path
import textwrap
import time
from typing import Any

from zeus_ros.atomic_file import replace_text

__all__ = ['TEACHER_SUFFIX', 'ContinualSettings', 'ResumePoint', 'RoundProgress',
           'append_history', 'field_docs', 'read_history', 'read_progress', 'resume_point']

TEACHER_SUFFIX = '.teacher.pt'
"""A deployed pixel student's state teacher is copied beside it (the trainer's OUT/deployed/)
under the student's name + this suffix, and found there again (continual_student.py): a
rollback, a restart or a relaunch from the copy still finds the teacher its actor came from
after the round folder its record names is pruned."""


@dataclass(frozen=True)
class ContinualSettings:
    """What one round does; defaults sized for a 2-core robot computer (tests shrink them)."""

    new_steps: int = 2000
    """Closed new steps that start a round (a novelty alarm may start one earlier)."""
    warmup_updates: int = 2000
    """Critic-only updates before the actor moves (deployment exports only): 200 left the
    critic too rough to steer a working actor (every candidate refused)."""
    updates: int = 2000
    """Actor + critic updates of a round."""
    actor_lr_scale: float = 0.3
    """The actor's learning rate in a round, as a fraction of its training one: small steps
    from a policy that works, against a critic that has seen little data."""
    bc_weight: float = 1.0
    """The round's actor_bc_weight (TD3+BC): the actor stays near the recorded actions.
    Measured offline on the zoo's Cheetah-Bias-v0 (6,000 steps at biases 0.6-0.9 + 6,000 at
    the train values): 0 wrecks the train values (-39 -> -308), 0.4 gains +38 on the new
    biases but loses up to 8 on train values, 1.0 gains +33 and loses at most 3."""
    bc_weight_new: float = 0.25
    """The anchor on the recorded steps (new contexts), per sample; `bc_weight` stays on the
    rehearsal (the train contexts). Strong where the robot must not forget, weak where the
    data is new (the spirit of CLEAR's replay + cloning, Rolnick et al. 2019, and of SPIBB,
    Laroche et al. 2019: leave the deployed policy only where the new data supports it).
    Negative: `bc_weight` everywhere (one anchor for all samples)."""
    gate_actor: bool = True
    """Keep the deployed actor at the train contexts and train an adapted copy that acts only
    where the policy's context is novel (learning/gated_actor.py; fitted on the rehearsal
    recording, so off without one). Measured on the drift scenario's recording: the plain
    fine-tune lost 3.6-4.9 per episode at train bias 0.3 in every setting tried."""
    old_ratio: float = 1.0
    """Old steps kept per new step in the replay mix."""
    max_old_steps: int = 20000
    """Cap on old steps in the mix: memory and update cost stay bounded."""
    rehearsal_steps: int = 8000
    """Steps at the family's train values, recorded once in-process by the first deployed
    checkpoint and part of every round (experience replay for continual learning, Rolnick et
    al. 2019): a recording that never visits the train values otherwise lets the candidate
    forget them (measured, first round of the drift scenario without it: +55 per episode on
    the new biases, -44 at train bias -0.3; refused; with 8,000 rehearsal steps the train
    values lose 1-6). 0: off (no simulator of the task)."""
    episodes: int = 20
    """Gate episodes per context value (paired: same initial states for both checkpoints).
    Measured on the drift scenario's recording: with 10 the stratified s.e. of the gain was
    8.6-12.8 (required 17-26 per episode, every candidate refused), with 20 it is 6.2-7.1
    (required 12-14); the gate takes twice as long (a minute at low priority)."""
    resume_refused: bool = True
    """Start the next round from a refused candidate that gained on the seen contexts (its
    critics too: no warm-up). Measured offline on the drift scenario's recording (rounds of
    2,000 updates, 20 gate episodes): from the deployed checkpoint every round gains about
    +11.5 per episode; continuing, +23.8 and +21.1 after the second and third round, with
    smaller losses on the train values. False: every round starts from the deployed one."""
    eval_seed: int = 300
    """Gate evaluation seed: initial states no training run chose."""
    max_seen_values: int = 6
    """Seen contexts evaluated by the gate (evenly spread over those recorded)."""
    max_train_values: int = 0
    """Train values evaluated by the gate, evenly spread (0: every one of the family's)."""
    margin: float = 1.0
    """Required mean gain of return per episode on the seen contexts (and >= 2 s.e.: with
    several episodes per value, the s.e. of the mean over the seen contexts, stratified by
    context; measured in the drift scenario, the spread across 6 values' means asked for
    +31 and refused a gain of +27.6 whose stratified 2 s.e. was at most 17.5)."""
    tolerance: float = 0.10
    """Allowed loss at any train value, as a fraction of |deployed return| there (and at least
    `tolerance_floor`); the live check after a swap allows the same loss."""
    tolerance_floor: float = 2.0
    """The least allowed loss at a train value, in return per episode, and at least 2 s.e. of
    that value's paired episode differences: a loss within its own noise is not called worse
    (far beyond the range one 40-step episode may earn -50 or -200 on a fall)."""
    seed: int = 0


def field_docs(cls: type) -> dict[str, str]:
    """Each dataclass field's docstring (the string under it), on one line.

    Python keeps no attribute docstrings at run time: read from the class's source, so that
    the trainer node's parameter descriptions are these texts, written once. A field without
    one is missing from the result; without the source (a .pyc-only install) all are.
    """
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return {}
    tree = ast.parse(textwrap.dedent(source))
    body = next(node for node in tree.body if isinstance(node, ast.ClassDef)).body
    names = {f.name for f in fields(cls)}
    docs = {}
    for statement, following in itertools.pairwise(body):
        if (isinstance(statement, ast.AnnAssign) and isinstance(statement.target, ast.Name)
                and statement.target.id in names and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)):
            docs[statement.target.id] = ' '.join(following.value.value.split())
    return docs


def append_history(path: Path | str, record: dict[str, Any]) -> dict[str, Any]:
    """Append one JSON line (with a UTC time) and fsync it: a crash keeps every decision."""
    record = {'time': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
              **record}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open('a', encoding='utf8') as handle:
        handle.write(json.dumps(record) + '\n')
        handle.flush()
        os.fsync(handle.fileno())
    return record


def read_history(path: Path | str) -> list[dict[str, Any]]:
    """Every record of a history file (a torn last line from a crash is skipped)."""
    path = Path(path)
    if not path.is_file():
        return []
    records = []
    for line in path.read_text('utf8').splitlines():
        try:
            records.append(json.loads(line))
        except ValueError:
            continue
    return records


PROGRESS_FILE = 'progress.json'
"""A running round's progress, in its folder (OUT/round_NNN/progress.json)."""


class RoundProgress:
    """Where a running round is: phase, counts, running gain, time to its decision.

    The round's process writes it (at most once per `every_s`, atomically); the node reads
    it and shows it on /diagnostics (and so in `zeus inspect`). `path` None: nowhere.
    """

    def __init__(self, path: Path | str | None, every_s: float = 1.0) -> None:
        self.path = None if path is None else Path(path)
        self.every_s = every_s
        self.started = time.monotonic()
        self._phase = ''
        self._phase_start = self.started
        self._written = 0.0
        self.fields: dict[str, Any] = {}

    def update(self, phase: str, done: int, total: int, force: bool = False,
               **extra: Any) -> None:
        """`done` of `total` in `phase` (training, gate, confirmation); `extra` adds figures."""
        now = time.monotonic()
        if phase != self._phase:
            self._phase, self._phase_start = phase, now
            self.fields = {}
        elapsed = now - self._phase_start
        eta = (elapsed / done * (total - done)) if done > 0 else None
        self.fields.update(extra)
        self.fields.update({'phase': phase, 'done': int(done), 'total': int(total),
                            'phase_eta_s': None if eta is None else round(eta, 1),
                            'round_s': round(now - self.started, 1)})
        if self.path is not None and (force or now - self._written >= self.every_s
                                      or done >= total):
            self._written = now
            replace_text(self.path, json.dumps(self.fields) + '\n')


def read_progress(folder: Path | str) -> dict[str, Any] | None:
    """The progress a running round wrote in `folder` (None: none yet, or torn)."""
    try:
        data = json.loads((Path(folder) / PROGRESS_FILE).read_text('utf8'))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


@dataclass
class ResumePoint:
    """Where a restarted trainer goes on: what its history says was decided last."""

    deployed: Path | None = None
    """The checkpoint the nodes ran last (its last swap, unless rolled back); None: the first."""
    resume: Path | None = None
    """The refused candidate the next round continues (None: start from the deployed one)."""
    rounds: int = 0
    """Rounds already run: the next one is rounds + 1 (its folder, its gate seeds)."""
    counts: dict[str, int] = field(default_factory=dict)
    """swaps, refusals, rollbacks, failures so far."""


def resume_point(records: list[dict[str, Any]]) -> ResumePoint:
    """The state a history ends in: deployed checkpoint, chain, round and decision counts.

    Files that no longer exist are not resumed from (the node then starts from its
    `checkpoint` parameter, or from the deployed one).
    """
    point = ResumePoint(counts={'swaps': 0, 'refusals': 0, 'rollbacks': 0, 'failures': 0})
    for record in records:
        event = record.get('event')
        point.rounds = max(point.rounds, int(record.get('round', 0) or 0))
        if event == 'swap':
            point.deployed, point.resume = Path(record['checkpoint']), None
            point.counts['swaps'] += 1
        elif event == 'live_check' and record.get('decision') == 'rollback':
            if record.get('rolled_back_to') and not record.get('error'):
                point.deployed = Path(record['rolled_back_to'])
                point.counts['rollbacks'] += 1
            point.resume = None
        elif event == 'gate' and record.get('decision') == 'refuse':
            point.counts['refusals'] += 1
        elif event == 'failure':
            point.counts['failures'] += 1
        elif event == 'chain':
            point.resume = Path(record['resume_from']) if record.get('resume_from') else None
    if point.deployed is not None and not point.deployed.is_file():
        point.deployed = None
    if point.resume is not None and not point.resume.is_file():
        point.resume = None
    return point
