"""continual_trainer: retrain from the growing recording, gate, swap live, roll back (issue 37).

Its own process, started by `zeus launch --continual` (`continual:=true`): background work by
design (`sched_batch`: Linux SCHED_BATCH at `nice` 0), so it keeps a fair share of the CPU on a
busy machine while the control loop's processes still run first whenever they wake. The main
thread waits for
`new_steps` closed new steps, then runs the round (train a candidate and gate it) in a child
process, `zeus continual-round` (zeus_ros/cli/continual_round.py over
zeus_ros/offline/training/continual.py), which inherits that priority and runs torch on
`threads` threads: each round's memory goes back to the OS when the child exits, and this
node never imports torch or the training code (nodes/ import nothing from offline/:
test/test_import_contract.py). It writes the round's request (JSON) to the round's folder,
logs the child's output line by line, and reads its answer (candidate, gate decision and
figures, where the next round starts); a shutdown during a round stops the child (SIGTERM,
SIGKILL after STOP_GRACE_S), a child that fails is logged and counted as a failed round. A
background thread spins the node (step and context-truth subscriptions, parameter clients,
/diagnostics). A candidate that passes is copied to OUT/deployed/ and set as `checkpoint` on
context_estimator and then policy (they pair by sha256: no mismatched pair ever acts); the
previous checkpoint stays on disk and is what a failed live check restores. A deployed pixel
student (`zeus launch --continual --obs pixels`) changes nothing here: its round trains and
gates the student's state teacher and answers with the refreshed student
(offline/training/continual_student.py); that is what is swapped, its teacher copied beside
it (TEACHER_SUFFIX), where the next round, a rollback or a restart finds it. Every decision is
one log line, one /diagnostics status and one line of OUT/history.jsonl. Operators pause and
resume rounds, run one now and swap the pair atomically through its services
(trainer_controls.py).

Installed as `continual_trainer_node`. Its parameters (SPECS) carry a description and a range
(`ros2 param describe`); a bad one stops it at start with one line (exit 2) and is refused
with the reason by `ros2 param set`. What a round does can change live (from the next round,
a `parameters` line in the history); its wiring, priority and novelty window cannot.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import asdict, fields, replace
import json
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import threading
import time
from typing import IO, Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from zeus_ros.atomic_file import replace_text
from zeus_ros.bags.kinds import REHEARSAL_FOLDER
from zeus_ros.bags.recording import closed_splits, split_steps
from zeus_ros.nodes.params import Spec, declare_specs, serve_live_changes
from zeus_ros.nodes.trainer_controls import TrainerControls
from zeus_ros.system.continual_settings import (
    TEACHER_SUFFIX,
    ContinualSettings,
    append_history,
    field_docs,
    read_history,
    read_progress,
    resume_point,
)
from zeus_ros.system.continual_watch import (
    LiveCheck,
    NoveltyAlarm,
    SegmentReturns,
    prune_recording,
)
from zeus_ros.system.processes import background_priority

TARGETS = ('context_estimator', 'policy')
"""Set in this order: the policy refuses the estimator's new estimates until it follows."""
SETTINGS = tuple(f.name for f in fields(ContinualSettings)
                 if f.name not in ('eval_seed', 'seed'))
"""What a round does: parameters of the same name, defaults from ContinualSettings."""
_SETTING_DOCS = field_docs(ContinualSettings)


def _setting(name: str, low: float | None = None, high: float | None = None) -> Spec:
    """A round's setting: its default and description are ContinualSettings' (written once)."""
    return Spec(getattr(ContinualSettings(), name),
                f"{_SETTING_DOCS.get(name, f'ContinualSettings.{name}')} (a live change "
                'applies from the next round)',
                live=True, low=low, high=high)


SPECS: dict[str, Spec] = {
    'recording': Spec('', "the recorder's output folder: rounds train on its closed splits "
                      '(zeus launch --continual sets it)', required=True,
                      allowed='a folder; it may not exist yet (the recorder makes it)'),
    'checkpoint': Spec('', 'the first deployed checkpoint, which context_estimator and policy '
                       'run at start: rounds continue from it (zeus launch --continual sets '
                       'it); the checkpoint deployed now is on /diagnostics', required=True,
                       allowed='an existing checkpoint file'),
    'out': Spec('', 'folder of history.jsonl, the round folders and the deployed copies',
                allowed="a folder (empty: the recording's path + _continual)"),
    'task': Spec('', 'the task family of the launch (zeus launch --task); not read: a round '
                 "takes the task from the deployed checkpoint and refuses another task's "
                 'recording', allowed='a task family name, or empty'),
    'new_steps': _setting('new_steps', 1),
    'warmup_updates': _setting('warmup_updates', 0),
    'updates': _setting('updates', 1),
    'actor_lr_scale': _setting('actor_lr_scale', 0.0, 10.0),
    'bc_weight': _setting('bc_weight', 0.0),
    'bc_weight_new': _setting('bc_weight_new', -1.0),
    'gate_actor': _setting('gate_actor'),
    'old_ratio': _setting('old_ratio', 0.0),
    'max_old_steps': _setting('max_old_steps', 0),
    'rehearsal_steps': _setting('rehearsal_steps', 0),
    'episodes': _setting('episodes', 1),
    'resume_refused': _setting('resume_refused'),
    'max_seen_values': _setting('max_seen_values', 1),
    'max_train_values': _setting('max_train_values', 0),
    'margin': _setting('margin', 0.0),
    'tolerance': _setting('tolerance', 0.0, 1.0),
    'tolerance_floor': _setting('tolerance_floor', 0.0),
    'threads': Spec(1, "torch threads of a round's child process (from the next round)",
                    live=True, low=1, high=256),
    'nice': Spec(0, "the trainer's nice value (its session's too: autogroup), inherited by "
                 'its rounds; 0: none', low=0, high=19),
    'sched_batch': Spec(True, 'run as Linux SCHED_BATCH: a fair share of the CPU, never '
                        "favoured when the control loop's processes wake"),
    'check_segments': Spec(2, 'complete context segments after a swap that the live check '
                           'compares with the previous checkpoint (from the next swap)',
                           live=True, low=1),
    'keep_recording_mb': Spec(2048, 'closed splits beyond this many MB are deleted, oldest '
                              'first (never those since the last swap)', live=True, low=1),
    'keep_candidates': Spec(5, 'newest round folders kept (and the one a chain continues); '
                            'deployed copies are all kept', live=True, low=1),
    'corrupt_rounds': Spec([0], 'drill: these rounds (numbered from 1; 0: none) train fresh '
                           'critics on negated rewards', live=True, low=0),
    'force_rounds': Spec([0], 'drill: these rounds (numbered from 1; 0: none) are swapped in '
                         'whatever the gate says, to exercise the rollback', live=True, low=0),
    'poll_s': Spec(1.0, 'seconds between looks at the recording (new closed splits, the live '
                   'check)', live=True, low=0.05, high=60.0),
    'novelty_window': Spec(200, "scored steps in the novelty alarm's window (0: no alarm)",
                           low=0),
    'novelty_fraction': Spec(0.5, 'the alarm is up while at least this share of the window '
                             "was outside the checkpoint's training contexts", low=0.01,
                             high=1.0),
    'novelty_min_steps': Spec(500, 'new closed steps that start a round while the novelty '
                              'alarm is up (instead of new_steps)', live=True, low=1),
}
"""The trainer's parameters: meaning, range, whether a change applies live. What a round does
is live from the next round; the process's wiring and priority and the alarm's shape are not."""
DEFAULTS: dict[str, Any] = {name: spec.default for name, spec in SPECS.items()}
"""Parameters; `corrupt_rounds` / `force_rounds` (round numbers from 1; 0: none) are drills:
that round trains on negated rewards / is swapped in whatever the gate says. A novelty alarm
(at least `novelty_fraction` of the last `novelty_window` scored steps outside the
checkpoint's training contexts; window 0: off) starts a round after `novelty_min_steps` new
closed steps instead of `new_steps`."""
ROUND_COMMAND = (sys.executable, '-m', 'zeus_ros.cli', 'continual-round')
"""The child process of a round (`zeus continual-round --request FILE`)."""
STOP_GRACE_S = 5.0
"""How long a round's child gets after SIGTERM (shutdown) before SIGKILL."""
REHEARSAL_ROOT = REHEARSAL_FOLDER
"""Beside the recording: one rehearsal per first checkpoint and size, kept across launches."""
TICK_S = 2.0
"""How often a running round's progress is published on /diagnostics."""
STDERR_LINES = 10
"""Last lines of a failed child's stderr kept in its failure line of history.jsonl."""


class ContinualTrainer(Node):
    """The ROS side: parameters, subscriptions, the swap and /diagnostics."""

    def __init__(self, **node_options: Any) -> None:
        """`node_options` go to rclpy's Node (cli_args, context: a test's own).

        Raises ValueError (one line) for a parameter out of its range (SPECS) or a checkpoint
        that is not a file.
        """
        super().__init__('continual_trainer', **node_options)
        p = declare_specs(self, SPECS)
        if not Path(p['checkpoint']).is_file():
            raise ValueError(f'continual_trainer: parameter checkpoint {p["checkpoint"]!r} is '
                             'not a file')
        self.p = p
        self.recording = Path(p['recording']).resolve()
        self.out = Path(p['out'] or f'{self.recording}_continual').resolve()
        self.history = self.out / 'history.jsonl'
        self.deployed = Path(p['checkpoint']).resolve()
        self.previous: Path | None = None
        self.settings = ContinualSettings(**{k: p[k] for k in SETTINGS})
        self.returns = SegmentReturns()
        self.lock = threading.Lock()
        self.state = 'waiting'
        self.progress: dict[str, str] = {}
        """The running round's progress (round_progress_values), shown on /diagnostics."""
        self.counts = {'rounds': 0, 'swaps': 0, 'refusals': 0, 'rollbacks': 0, 'failures': 0}
        from diagnostic_msgs.msg import DiagnosticArray
        from zeus_msgs.msg import ContextTruth, StepFeedback

        from zeus_ros.nodes.topics import TOPICS, step_qos

        self.diagnostics = self.create_publisher(DiagnosticArray, TOPICS.DIAGNOSTICS, 10)
        self.create_subscription(StepFeedback, TOPICS.STEP, self._on_step, step_qos(100))
        self.create_subscription(ContextTruth, TOPICS.CONTEXT_TRUTH, self._on_truth,
                                 step_qos(100))
        self.novelty = NoveltyAlarm(int(p['novelty_window']), float(p['novelty_fraction']))
        if self.novelty.window:
            self.create_subscription(ContextTruth, TOPICS.CONTEXT_NOVELTY, self._on_novelty,
                                     step_qos(100))
        from rclpy.parameter_client import AsyncParameterClient

        self.clients_ = {name: AsyncParameterClient(self, name) for name in TARGETS}
        self.create_timer(5.0, lambda: self.report('status'))
        serve_live_changes(self, SPECS, self.p, self._changed)
        self.controls = TrainerControls(self)

    def _changed(self, changed: dict[str, Any]) -> None:
        """A live change: the round's settings anew (read at the next round), a history line."""
        settings = {k: v for k, v in changed.items() if k in SETTINGS}
        if settings:
            self.settings = replace(self.settings, **settings)
        append_history(self.history, {'event': 'parameters', 'changed': {
            k: list(v) if isinstance(v, list | tuple) or hasattr(v, 'typecode') else v
            for k, v in changed.items()}})

    def _on_step(self, msg: Any) -> None:
        with self.lock:
            self.returns.on_step(msg.reward, msg.first)

    def _on_novelty(self, msg: Any) -> None:
        names = list(msg.names)
        if 'novel' in names and len(msg.values) == len(names):  # else not the estimator's
            with self.lock:
                self.novelty.on_novelty(msg.values[names.index('novel')] > 0.5)

    def _on_truth(self, msg: Any) -> None:
        with self.lock:
            self.returns.on_truth(msg.segment, msg.values)

    def report(self, event: str, message: str = '', problem: bool = False) -> None:
        """One /diagnostics status: the state, the counts, the deployed checkpoint."""
        from zeus_ros.nodes.messages import diagnostics_message

        values = {'event': event, 'state': self.state, 'paused': self.controls.paused,
                  'deployed': str(self.deployed),
                  'previous': str(self.previous or ''), 'history': str(self.history),
                  **self.counts, **self.progress}
        if message:
            values['decision'] = message
        self.diagnostics.publish(diagnostics_message(self, 'continual', values,
                                                     [message] if problem else []))

    def set_checkpoint(self, path: Path, timeout: float = 30.0) -> str | None:
        """Both nodes on `path`; None, or why it failed (the pair stays on its checkpoint).

        Through the atomic pair swap (pair_swap.py: the policy stages it, switches with the
        estimator's first estimate of it: no step is acted on by a mismatched pair) when the
        policy offers it; else the two parameters one after the other, estimator first.
        Called from the main thread; the swap runs on the spinning executor.
        """
        swapper, executor = self.controls.swapper, self.executor
        if executor is not None and swapper.stage.wait_for_service(timeout_sec=2.0):
            task = executor.create_task(swapper.swap(str(path), ''))
            end = time.monotonic() + timeout
            while not task.done() and time.monotonic() < end:
                time.sleep(0.01)
            if not task.done():
                task.cancel()
                return f'the pair swap did not answer within {timeout:g} s'
            error = task.exception()
            return None if error is None else str(error)
        return self._set_parameters(path, timeout)

    def _set_parameters(self, path: Path, timeout: float) -> str | None:
        """The pair's `checkpoint` parameters, estimator first (a policy without staging)."""
        done: list[str] = []
        for name in TARGETS:
            client = self.clients_[name]
            if not client.wait_for_services(timeout_sec=timeout):
                why = f'{name} offers no parameter services'
            else:
                future = client.set_parameters([Parameter('checkpoint', value=str(path))])
                end = time.monotonic() + timeout
                while not future.done() and time.monotonic() < end:
                    time.sleep(0.01)
                result = future.result() if future.done() else None
                ok = result is not None and all(r.successful for r in result.results)
                why = '' if ok else (f'{name} refused it: '
                                     + (result.results[0].reason if result else 'no answer'))
            if why:
                for other in done:  # the pair stays matched
                    self.clients_[other].set_parameters(
                        [Parameter('checkpoint', value=str(self.deployed))])
                return why
            done.append(name)
        return None


class Trainer:
    """The main-thread loop: wait, train, gate, swap, watch, prune."""

    def __init__(self, node: ContinualTrainer, stop: threading.Event) -> None:
        self.node = node
        self.stop = stop
        self.log = node.get_logger()
        self.since_swap: list[Path] = []
        self.used: set[Path] = set()
        """Splits of the rounds before the last swap: old data from then on."""
        self.steps_at_round = 0
        self.watch: LiveCheck | None = None
        self.since_segment = 0
        """First segment of the deployed checkpoint: its live baseline starts there."""
        self.episode_length = 0
        """The task's episode length (the live check's scale), from the first round's answer."""
        self.resume: Path | None = None
        """A refused candidate the next round continues (continual.resume_from)."""

    def run(self) -> None:
        """Until stopped: one poll every poll_s seconds."""
        n = self.node
        n.out.mkdir(parents=True, exist_ok=True)
        resumed = self.resume_history()
        self.log.info(f'continual: deployed {n.deployed}; recording {n.recording}; history '
                      f'{n.history}; a round every {n.settings.new_steps} new closed steps')
        append_history(n.history, {'event': 'start', 'deployed': str(n.deployed),
                                   'recording': str(n.recording), 'resumed': resumed})
        while not self.stop.wait(float(n.p['poll_s'])):
            self.poll()

    def resume_history(self) -> dict[str, Any] | None:
        """Go on where an earlier trainer on this recording stopped (its history.jsonl).

        The checkpoint it deployed last is set on both nodes again (a restarted launch starts
        them on the first one), the chain of refused candidates continues, round numbers go
        on. None when there is nothing to resume.
        """
        n = self.node
        point = resume_point(read_history(n.history))
        if not point.rounds:
            return None
        n.counts.update(point.counts, rounds=point.rounds)
        self.resume = point.resume
        if point.deployed is not None and point.deployed.resolve() != n.deployed:
            why = n.set_checkpoint(point.deployed)
            if why is None:
                n.deployed = point.deployed.resolve()
            else:
                self.log.error(f'continual: could not redeploy {point.deployed} from the '
                               f'history ({why}); {n.deployed} runs on')
                self.resume = None
        self.log.info(f'continual: resumed after round {point.rounds} from {n.history}: '
                      f'deployed {n.deployed.name}'
                      + (f', the next round continues {self.resume}' if self.resume else ''))
        return {'rounds': point.rounds, 'deployed': str(n.deployed),
                'resume_from': None if self.resume is None else str(self.resume)}

    def poll(self) -> None:
        """Check a swap under watch, then start a round when enough new steps are closed."""
        n, controls = self.node, self.node.controls
        if controls.swapped:  # an operator's swap: the round's live check compares no more
            controls.swapped, self.watch = False, None
        self.check_live()
        splits = closed_splits(n.recording)
        known = {p.resolve() for p in self.since_swap}
        self.since_swap += [b for b in splits if b.resolve() not in known
                            and b.resolve() not in self.used]
        controls.new_splits = len(self.since_swap)
        total = sum(split_steps(b) for b in self.since_swap)
        with n.lock:
            novel = n.novelty.raised
        needed = min(n.settings.new_steps, int(n.p['novelty_min_steps'])) if novel \
            else n.settings.new_steps
        asked, controls.round_asked = controls.round_asked, False
        if not asked and (controls.paused or self.watch is not None
                          or total - self.steps_at_round < needed):
            return
        trigger = 'operator' if asked else (
            'novelty alarm' if total - self.steps_at_round < n.settings.new_steps
            else 'new steps')
        self.steps_at_round = total
        self.round(splits, trigger)
        removed = prune_recording(closed_splits(n.recording),
                                  int(n.p['keep_recording_mb'] * 1e6), self.since_swap)
        if removed:
            self.log.info(f'continual: retention: deleted {len(removed)} oldest split(s) '
                          f'({", ".join(b.name for b in removed)}) to stay under '
                          f'{n.p["keep_recording_mb"]} MB')

    def round(self, splits: list[Path], trigger: str = 'new steps') -> None:
        """Train and gate a candidate (a child process); swap it in when it passes or is forced."""
        n = self.node
        n.counts['rounds'] += 1
        number = n.counts['rounds']
        new = self._newest(self.since_swap, 4 * n.settings.new_steps)
        corrupt = number in n.p['corrupt_rounds']
        forced = number in n.p['force_rounds']
        n.state = 'training'
        n.report('round', f'round {number} ({trigger}): training on {len(new)} new split(s)')
        append_history(n.history, {'event': 'round', 'round': number, 'trigger': trigger,
                                   'new_splits': len(new)})
        folder = n.out / f'round_{number:03d}'
        request = {
            'deployed': str(n.deployed), 'first_checkpoint': str(Path(n.p['checkpoint'])),
            'rehearsal': str(n.recording.parent / REHEARSAL_ROOT),
            'new_bags': [str(b) for b in new],
            'splits': [str(b) for b in splits], 'out': str(folder), 'history': str(n.history),
            'settings': asdict(n.settings), 'corrupt_rewards': corrupt, 'forced': forced,
            'resume_from': None if self.resume is None else str(self.resume),
            'threads': max(1, int(n.p['threads'])), 'parent_pid': os.getpid(), 'round': number,
            'result': str(folder / 'result.json')}
        def tick() -> None:
            n.progress = round_progress_values(read_progress(folder))
            n.report('progress')

        answer = run_child_round(folder, request, self.log.info, self.stop, tick)
        n.progress = {}
        if answer['status'] == 'stopped':
            self.log.info(f'continual: round {number} stopped: shutting down')
            append_history(n.history, {'event': 'stopped', 'round': number,
                                       'progress': read_progress(folder)})
            return
        if answer['status'] != 'done':  # a bad split, a diverged candidate: the robot runs on
            n.counts['failures'] += 1
            n.state = 'waiting'
            line = f'continual: round {number} failed: {answer["error"]}: {answer["reason"]}'
            self.log.error(line)
            append_history(n.history, {'event': 'failure', 'round': number,
                                       'reason': answer['reason'],
                                       **({'stderr': answer['stderr']} if answer['stderr']
                                          else {})})
            n.report('failure', line, problem=True)
            return
        n.state = 'waiting'
        self.resume = Path(answer['resume_from']) if answer['resume_from'] else None
        append_history(n.history, {'event': 'chain', 'round': number,
                                   'resume_from': answer['resume_from']})
        self.episode_length = self.episode_length or int(answer['episode_length'])
        if not answer['deploy'] and not forced:
            n.counts['refusals'] += 1
            refused = answer.get('teacher_sha256') or answer['sha256']  # a student's teacher
            n.report('refuse', f'round {number}: refused {refused[:12]}: {answer["reason"]}')
        else:
            self.swap(answer, number, forced and not answer['deploy'])
        self._prune_candidates()

    def swap(self, answer: dict[str, Any], number: int, forced: bool) -> None:
        """Copy the candidate to OUT/deployed, set it on both nodes, start the live watch."""
        n = self.node
        sha256 = str(answer['sha256'])
        target = n.out / 'deployed' / f'round_{number:03d}_{sha256[:12]}.pt'
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(answer['candidate'], target)
        teacher: dict[str, str] = {}  # a pixel student's state teacher, beside it
        if answer.get('teacher_candidate'):
            copy = target.with_name(target.stem + TEACHER_SUFFIX)
            shutil.copy2(answer['teacher_candidate'], copy)
            teacher = {'teacher': str(copy), 'teacher_sha256': answer['teacher_sha256']}
        why = n.set_checkpoint(target)
        if why is not None:
            n.counts['failures'] += 1
            line = f'continual: swap of round {number} failed ({why}); {n.deployed} runs on'
            self.log.error(line)
            append_history(n.history, {'event': 'swap_failed', 'round': number,
                                       'reason': why})
            n.report('swap_failed', line, problem=True)
            return
        n.previous, n.deployed = n.deployed, target
        n.counts['swaps'] += 1
        gain = float(answer['gain'])
        with n.lock:
            segment = n.returns.current
        self.watch = LiveCheck(segment, self.since_segment, gain, n.settings.tolerance,
                               n.settings.tolerance_floor, self.episode_length,
                               int(n.p['check_segments']))
        self.since_segment = segment + 1
        self.used |= {p.resolve() for p in self.since_swap}
        self.since_swap, self.steps_at_round = [], 0
        line = (f'continual: SWAPPED in {target.name} ({sha256[:12]})'
                f'{" FORCED past the gate" if forced else ""}; previous {n.previous.name} kept; '
                f'live check over {self.watch.segments} segments paired by context with the '
                f"previous checkpoint's (gate gain {gain:+.1f} per episode)")
        self.log.info(line)
        append_history(n.history, {'event': 'swap', 'round': number, 'checkpoint': str(target),
                                   'sha256': sha256, **teacher, 'forced': forced,
                                   'previous': str(n.previous), 'gate_gain': gain})
        n.report('swap', line)

    def check_live(self) -> None:
        """Roll back a swap that earns less live than its predecessor on the same contexts."""
        n = self.node
        if self.watch is None:
            return
        with n.lock:
            verdict = self.watch.verdict(n.returns)
        if verdict is None:
            return
        decision, change, allowed = verdict
        watch, self.watch = self.watch, None
        record = {'event': 'live_check', 'checkpoint': str(n.deployed), 'live_change': change,
                  'allowed': allowed, 'gate_gain': watch.gain, 'decision': decision}
        figures = (f'live {change:+.1f} per episode against the previous checkpoint on the same '
                   f'contexts (gate {watch.gain:+.1f}, allowed -{allowed:.1f})')
        if decision == 'keep':
            line = f'continual: live check kept {n.deployed.name}: {figures}'
            self.log.info(line)
            append_history(n.history, record)
            n.report('keep', line)
            return
        assert n.previous is not None
        why = n.set_checkpoint(n.previous)
        if why is None:
            n.counts['rollbacks'] += 1
            bad, n.deployed, n.previous = n.deployed, n.previous, None
            self.resume = None  # nothing trained from the rolled-back one continues
            self.since_segment = watch.since_segment  # the restored one's segments count again
            line = f'continual: ROLLED BACK {bad.name} -> {n.deployed.name}: {figures}'
        else:
            line = f'continual: rollback of {n.deployed.name} failed: {why}'
        self.log.warning(line)
        append_history(n.history, {**record, 'rolled_back_to': str(n.deployed),
                                   'error': why})
        n.report('rollback', line, problem=True)

    @staticmethod
    def _newest(splits: list[Path], steps: int) -> list[Path]:
        """The newest splits holding at most `steps` steps (at least one)."""
        chosen: list[Path] = []
        total = 0
        for bag in reversed(splits):
            total += split_steps(bag)
            if chosen and total > steps:
                break
            chosen.append(bag)
        return sorted(chosen)

    def _prune_candidates(self) -> None:
        """Keep the newest `keep_candidates` round folders (deployed copies are all kept)."""
        rounds = sorted(self.node.out.glob('round_*'))
        for folder in rounds[:-int(self.node.p['keep_candidates'])]:
            if self.resume is not None and folder in self.resume.parents:
                continue  # the next round continues this candidate
            shutil.rmtree(folder, ignore_errors=True)


def round_progress_values(progress: dict[str, Any] | None) -> dict[str, str]:
    """A round's progress file (RoundProgress) as /diagnostics values (strings)."""
    if not progress:
        return {}
    values = {'round_phase': str(progress.get('phase', '')),
              'round_progress': f"{progress.get('done', 0)}/{progress.get('total', 0)}"}
    if progress.get('gain') is not None:
        se = progress.get('gain_se')
        values['round_gain'] = (f"{progress['gain']:+.1f}"
                                + (f' ± {se:.1f}' if se is not None else ''))
    if progress.get('phase_eta_s') is not None:
        values['round_phase_eta_s'] = f"{progress['phase_eta_s']:.0f}"
    return values


def run_child_round(folder: Path, request: dict[str, Any], log: Callable[[str], None],
                    stop: threading.Event, tick: Callable[[], None] | None = None
                    ) -> dict[str, Any]:
    """Run one round in `zeus continual-round` and return its answer (cli/continual_round.py).

    Writes `request` to `folder`/request.json; the child's stdout lines go to `log`, its stderr
    to this process's stderr (the last STDERR_LINES kept). While it runs, `stop` is watched:
    once set, the child gets SIGTERM (its training stops at the next check) and SIGKILL after
    STOP_GRACE_S; the answer is then {'status': 'stopped'}, unless the round had finished
    (its gate line written): that answer counts, as it did when the round ran in-process. A
    child that exits without a readable answer, or stopped by a signal from elsewhere, is
    {'status': 'failed', 'error': 'RoundProcessError', 'reason': ...}; every answer but
    'stopped' carries `stderr`, the child's last stderr lines.
    """
    folder.mkdir(parents=True, exist_ok=True)
    result = Path(request['result'])
    result.unlink(missing_ok=True)
    replace_text(folder / 'request.json', json.dumps(request, indent=1) + '\n')
    env = {**os.environ, 'OMP_NUM_THREADS': str(request['threads']),
           'MKL_NUM_THREADS': str(request['threads'])}
    child = subprocess.Popen([*ROUND_COMMAND, '--request', str(folder / 'request.json')],
                             stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, env=env, text=True, bufsize=1)
    tail: deque[str] = deque(maxlen=STDERR_LINES)
    readers = [threading.Thread(target=_pump, args=(child.stdout, log, None), daemon=True),
               threading.Thread(target=_pump, args=(child.stderr, _to_stderr, tail),
                                daemon=True)]
    for reader in readers:
        reader.start()
    stopped = False
    ticked = time.monotonic()
    while child.poll() is None:
        if tick is not None and time.monotonic() - ticked >= TICK_S:
            ticked = time.monotonic()
            tick()
        if stop.wait(0.2):
            stopped = True
            child.send_signal(signal.SIGTERM)
            try:
                child.wait(timeout=STOP_GRACE_S)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
    for reader in readers:
        reader.join(timeout=2.0)
    try:
        answer = json.loads(result.read_text('utf8'))
        if answer.get('status') not in ('done', 'stopped', 'failed'):
            raise ValueError(f'unknown status {answer.get("status")!r}')
    except (OSError, ValueError, AttributeError) as error:
        if stopped:
            return {'status': 'stopped'}
        code = child.returncode
        ended = (f'was killed by signal {-code}' if code < 0 else f'exited with code {code}')
        last = f'; last stderr line: {tail[-1]}' if tail else ''
        answer = {'status': 'failed', 'error': 'RoundProcessError',
                  'reason': f'the round process {ended} without an answer ({error}){last}'}
    if stopped and answer['status'] != 'done':  # a round that finished still counts
        return {'status': 'stopped'}
    if answer['status'] == 'stopped':  # not by this node: someone else signalled the child
        answer = {'status': 'failed', 'error': 'RoundProcessError',
                  'reason': 'the round process was stopped by a signal from outside the node'}
    return {**answer, 'stderr': list(tail)}


def _pump(stream: IO[str] | None, sink: Callable[[str], None],
          tail: deque[str] | None) -> None:
    """Every line of `stream` to `sink` (and `tail`) until the child closes it."""
    if stream is None:
        return
    with stream:
        for line in stream:
            line = line.rstrip('\n')
            if tail is not None:
                tail.append(line)
            sink(line)


def _to_stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def main(args: list[str] | None = None) -> int:
    """Entry point: `continual_trainer_node --ros-args -p recording:=... -p checkpoint:=...`.

    (or `python -m zeus_ros.nodes.continual_node`, as `zeus launch` starts it). A bad params
    file or parameter is one `error:` line and exit code 2, as for the other nodes.
    """
    from rclpy.signals import SignalHandlerOptions

    from zeus_ros.nodes.spin import params_file_errors

    bad = params_file_errors(sys.argv[1:] if args is None else args)
    if bad:
        print(f'error: {bad[0]}', file=sys.stderr)
        return 2
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = ContinualTrainer()
    except ValueError as error:
        print(f'error: {error}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    # The rounds' child processes inherit it (system/processes.background_priority).
    priority = background_priority(int(node.p['nice']), bool(node.p['sched_batch']))
    node.get_logger().info(f'continual: trainer priority: {priority}')
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=lambda: _spin(executor, stop), daemon=True)
    spinner.start()
    try:
        Trainer(node, stop).run()
    finally:
        stop.set()
        spinner.join(timeout=2)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _spin(executor: SingleThreadedExecutor, stop: threading.Event) -> None:
    while not stop.is_set():
        try:
            executor.spin_once(timeout_sec=0.1)
        except Exception:  # shutting down
            break


if __name__ == '__main__':
    raise SystemExit(main())
