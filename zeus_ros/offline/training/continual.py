"""Continual deployment, the ROS-free half: closed splits -> candidate -> gate -> history.

The live trainer (zeus_ros/nodes/continual_node.py) runs one round (`run_round`, over
`continual_round`) whenever enough new steps are recorded, each in a child process
(`zeus continual-round`, zeus_ros/cli/continual_round.py); everything it decides is computed
here, so it is tested without ROS. The settings and the history file are shared with the node
(zeus_ros/system/continual_settings.py), the closed splits come from
zeus_ros/bags/recording.py.

- **Data.** Only closed splits of the growing recording are read (`closed_splits`: metadata
  says `closed` or `recovered`, or was written at close), never the bag being written.
- **Replay mix.** Every split new since the last swap, plus older splits drawn at random up to
  `old_ratio` x the new steps (default 1: half old, half new) and at most `max_old_steps`. The
  old half keeps the contexts already handled in the batches, so fitting the new ones does not
  overwrite them (forgetting is what the gate's train values check); the cap bounds memory and
  update cost however long the robot runs, and a uniform draw over the older splits keeps the
  whole past represented rather than only the most recent hours.
- **Continuing from the deployed checkpoint.** A deployment export (the zoo) has encoder, psi
  and actor but no critics: a fresh critic is built and first trained alone for
  `warmup_updates` (actor frozen: its update period is set beyond the warm-up), so the actor's
  first gradient comes from a critic that already values its own behaviour. A full checkpoint
  (an earlier candidate) brings its critics and optimizers and skips the warm-up. phi and psi
  stay frozen throughout (`representation_frozen_from: 1`): with a few hundred updates on a few
  thousand steps, retraining the context space from fresh dynamics models would move every
  context the deployed actor relies on; the candidate learns to act on the deployed context
  space instead, and the estimator and policy of a swap still share one file.
- **Rehearsal.** `rehearsal_bag` records `rehearsal_steps` at the family's train values once
  (the deployed checkpoint acting, a little noise) and every round trains on it too: the old
  splits of a run that drifted away never show the train contexts again.
- **The gated actor.** With a rehearsal, the candidate's actor is wrapped in a GatedActor
  (learning/gated_actor.py) fitted on the rehearsal's per-step contexts: the deployed actor
  acts wherever the context is familiar, a trained copy where it is novel, so a round cannot
  forget the train contexts. The behaviour-cloning anchor is per sample (`bc_weight` on the
  rehearsal, `bc_weight_new` on the recording).
- **Progress across refusals.** A refused candidate that still gained on the seen contexts
  (`resume_refused`) is where the next round starts, critics and all (no warm-up); the gate
  always compares against the deployed checkpoint, so a chain of rounds only accumulates
  updates, never trust. A swap, a rollback or a round that gained nothing starts afresh.
- **Gate.** Candidate and deployed checkpoint are evaluated in-process on the same seeds (the
  same initial states per value), fresh for every round (`ROUND_SEED`): on the contexts seen
  in the new splits (the recording's context truth; on a robot without truth, the deployed
  checkpoint's read-out of them: continual_seen.py) and on the family's train values. One
  decision where the robot runs: the mean gain over the seen contexts is at least
  max(`margin`, 2 s.e.), the s.e. that of a mean over these contexts, stratified by context
  (each paired episode a sample of its context's difference; with one episode per value the
  spread across values stands in). And a forgetting budget where it was trained: no train
  value worse than max(`tolerance_floor`, `tolerance` x |deployed return there|, 2 s.e. of
  that value's paired episode differences). A candidate that passes is confirmed by the same
  rule on other fresh initial states (`CONFIRM_SEED`) before it is deployed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
import json
from pathlib import Path
import shutil
import time
from typing import Any

import numpy as np

from zeus_ros.bags.recording import split_steps
from zeus_ros.offline.training.continual_gate import GateResult, gate
from zeus_ros.system.continual_settings import (
    PROGRESS_FILE,
    ContinualSettings,
    RoundProgress,
    append_history,
)

__all__ = ['Candidate', 'GateResult', 'RoundResult', 'RoundStopped', 'continual_round', 'gate',
           'rehearsal_bag', 'replay_mix', 'resume_from', 'run_round', 'train_candidate']

CORRUPTION = -1.0
"""The drill's corrupted rewards: every reward times this (negated: the opposite task). Scaled
up (x -10) the TD errors grow so large that a weak policy's round can land anywhere, better
included (measured once: +126 on a weak Cheetah-Run-v0 policy), so the drill stays a flip.
The drill also starts from fresh critics (warmed up on the corrupted rewards): a trained
critic's values dominate a few hundred TD targets (r + gamma Q', with Q near r / (1 - gamma)),
so an actor trained against it keeps improving on the true task whatever the rewards say
(measured: a negated-reward round of 800 updates continuing a competent critic earned +31.5
per episode on Cheetah-Run-v0, and the gate rightly deployed it). A critic learned from the
corrupted rewards alone is what a reward bug produces."""
CONFIRM_SEED = 500
"""Offset of the confirmation's evaluation seed from the round's gate seed."""
ROUND_SEED = 1000
"""Offset of each round's gate seed: a chain of candidates is never selected on the same
initial states again and again (round r evaluates on eval_seed + r x ROUND_SEED)."""
WARMUP_ACTOR_PERIOD = 10**9
"""actor_update_freq during the critic warm-up: no warm-up update index is a multiple of it."""


class RoundStopped(Exception):  # noqa: N818 - a request, not an error
    """A shutdown asked a round to stop: nothing was written."""


@dataclass
class Candidate:
    """A trained candidate checkpoint and what it was trained on."""

    path: Path
    sha256: str
    new_bags: list[str]
    old_bags: list[str]
    transitions: int
    updates: int
    warmup_updates: int
    seconds: float
    seen: list[dict[str, float]] = field(default_factory=list)
    seen_from: str = 'truth'
    """Where `seen` came from: 'truth', 'read-out', or 'none' (the gate uses the train
    values)."""


@dataclass
class RoundResult:
    """One round: the candidate, the gate, and the history record written."""

    candidate: Candidate
    gate: GateResult
    record: dict[str, Any]


# ---------------------------------------------------------------------- data
def replay_mix(splits: Sequence[Path], new: Sequence[Path], settings: ContinualSettings
               ) -> list[Path]:
    """The old splits of a round: a seeded uniform draw over the splits before `new`."""
    fresh = {Path(b).resolve() for b in new}
    old = [b for b in splits if Path(b).resolve() not in fresh]
    budget = min(settings.old_ratio * sum(split_steps(b) for b in new), settings.max_old_steps)
    rng = np.random.default_rng(settings.seed + len(splits))
    chosen: list[Path] = []
    used = 0
    for index in rng.permutation(len(old)):
        steps = split_steps(old[index])
        if used + steps > budget:
            continue
        chosen.append(old[index])
        used += steps
    return sorted(chosen)


REHEARSAL_NOISE = 0.1
"""Exploration noise of the rehearsal recording (the critic needs actions to compare)."""
REHEARSAL_EVERY = 200
"""Steps per train value in the rehearsal recording."""


def rehearsal_bag(deployed: Path | str, folder: Path | str, settings: ContinualSettings,
                  log: Callable[[str], None] = print) -> Path | None:
    """`folder`/bag_000: `rehearsal_steps` at the family's train values (made once).

    None when off or when the task has no train values. Written under a temporary name and
    renamed when closed, so a crash never leaves a half recording that looks complete.
    """
    if settings.rehearsal_steps <= 0:
        return None
    folder = Path(folder)
    bag = folder / 'bag_000'
    if (bag / 'metadata.yaml').is_file():
        return bag
    from sim_bridge.env import ScheduledEnv
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config
    from zeus_ros.bags.kinds import BagLabel
    from zeus_ros.bags.writer import StepBagWriter
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.rollout import AgentPolicy, collect

    begin = time.perf_counter()
    agent = InferenceAgent.from_checkpoint(deployed, reuse_features=True)
    task = make_task(agent.task, seed=settings.seed)
    try:
        schedule = schedule_from_config({'kind': 'switch', 'values': 'train',
                                         'every': REHEARSAL_EVERY}, task, settings.seed)
    except (KeyError, TypeError, ValueError) as error:
        task.close()
        log(f'continual: no rehearsal ({agent.task} has no train values: {error})')
        return None
    partial = folder / 'bag_000.partial'
    if partial.exists():
        shutil.rmtree(partial)
    folder.mkdir(parents=True, exist_ok=True)
    policy = AgentPolicy(agent, noise=REHEARSAL_NOISE, seed=settings.seed)
    try:
        with StepBagWriter(partial, pixels=agent.obs_kind == 'pixels', label=BagLabel(
                'rehearsal', task=agent.task, checkpoint=str(deployed))) as writer:
            collect(ScheduledEnv(task, schedule), task, policy, writer,
                    settings.rehearsal_steps, progress=False)
    finally:
        task.close()
    partial.rename(bag)
    log(f'continual: rehearsal recording {bag}: {settings.rehearsal_steps} steps at the '
        f'train values in {time.perf_counter() - begin:.1f} s')
    return bag


# ---------------------------------------------------------------------- candidate
def _agent_from(deployed: Path, fresh_critics: bool = False) -> tuple[Any, bool]:
    """An agent that can train, from `deployed`; True when its critics are fresh.

    A deployment export has no critics; `fresh_critics` drops those of a full checkpoint too.
    """
    from zeus_ros.learning.agent import ZeusAgent
    from zeus_ros.learning.checkpoint import DEPLOY_MODULES, load_checkpoint

    loaded = load_checkpoint(deployed, load_optimizers=False)
    config = loaded.config.replace(device='cpu')
    if not loaded.deploy and not fresh_critics:
        full = load_checkpoint(deployed, map_location='cpu').agent
        full.config = config
        return full, False
    agent = ZeusAgent(config, loaded.spec, device='cpu')
    acting = {name: loaded.agent.modules[name].state_dict()
              for name in DEPLOY_MODULES if name in agent.modules}
    for name, state in acting.items():
        agent.modules[name].load_state_dict(state)
    for source, target in (('encoder', 'encoder_target'), ('psi', 'psi_target')):
        if target in agent.modules:
            agent.modules[target].load_state_dict(acting[source])
    agent.log_alpha.data.copy_(loaded.agent.log_alpha.detach())
    return agent, True


def train_candidate(deployed: Path | str, new_bags: Sequence[Path], old_bags: Sequence[Path],
                    out: Path | str, settings: ContinualSettings, *,
                    corrupt_rewards: bool = False, log: Callable[[str], None] = print,
                    stop: Callable[[], bool] = lambda: False,
                    readout_from: Path | str | None = None,
                    rehearsal: Path | None = None,
                    progress: RoundProgress | None = None) -> Candidate:
    """Continue `deployed` (or an earlier candidate) on new + old bags; write `out`/candidate.pt.

    `corrupt_rewards` multiplies every reward by CORRUPTION: the deliberately bad candidate
    the gate must refuse. `stop` is asked every 50 updates (a shutdown: RoundStopped).
    `readout_from`: the checkpoint whose read-out names the seen contexts of a recording
    without context truth (continual_seen.py; default `deployed`). `rehearsal`: the
    rehearsal bag among `old_bags` (anchored with `bc_weight`, the rest with
    `bc_weight_new`).
    Raises TrainError (bad data, another task, non-finite training).
    """
    from zeus_ros.learning.checkpoint import save_checkpoint
    from zeus_ros.learning.errors import CheckpointError
    from zeus_ros.offline.data.ingest import ingest_bags
    from zeus_ros.offline.data.replay import ReplayBuffer
    from zeus_ros.offline.evaluation.records import checkpoint_sha256
    from zeus_ros.offline.training.continual_seen import seen_contexts
    from zeus_ros.offline.training.train import TrainError

    begin = time.perf_counter()
    out = Path(out)
    agent, fresh_critic = _agent_from(Path(deployed), fresh_critics=corrupt_rewards)
    dataset = ingest_bags([*new_bags, *old_bags])
    if dataset.task != agent.spec.task:
        raise TrainError(f'the recording holds {dataset.task}, the deployed checkpoint '
                         f'{deployed} runs {agent.spec.task}')
    seen = seen_contexts(readout_from or deployed,
                         ingest_bags(list(new_bags)) if old_bags else dataset,
                         settings.max_seen_values)
    if seen.source != 'truth':
        log(f'continual: no context truth in the new splits; seen contexts: '
            f'{seen.source} ({seen.detail})')
    if corrupt_rewards:
        dataset.episodes = [replace(ep, reward=CORRUPTION * ep.reward) for ep in dataset.episodes]
    if settings.gate_actor and rehearsal is not None and not agent.config.actor_gate:
        _gate(agent, ingest_bags([rehearsal]), settings, log)
    config = agent.config
    for group in agent.optimizers['actor'].param_groups:
        group['lr'] = config.actor_lr * settings.actor_lr_scale
    replay = ReplayBuffer(dataset, history=config.k, pixels=config.obs_kind == 'pixels',
                          seed=settings.seed, model_horizon=config.model_horizon,
                          anchor=_anchor(settings, rehearsal))
    if len(replay) < config.batch_size:
        raise TrainError(f'{len(replay)} transitions, fewer than one batch '
                         f'({config.batch_size}); wait for more steps')
    frozen = config.replace(representation_frozen_from=1, actor_bc_weight=settings.bc_weight)
    warmup = settings.warmup_updates if fresh_critic else 0
    needs_pair = agent.objective.needs_pair(config)
    start = step = max(agent_step(Path(deployed)), 1)
    phases = ((frozen.replace(actor_update_freq=WARMUP_ACTOR_PERIOD), warmup),
              (frozen, settings.updates))
    for phase_config, count in phases:
        agent.config = phase_config
        for index in range(count):
            if index % 50 == 0:
                if stop():
                    raise RoundStopped(f'stopped at update {step}')
                if progress is not None:
                    progress.update('training', step - start, warmup + settings.updates,
                                    warmup_updates=warmup)
            pair = replay.sample(config.batch_size) if needs_pair else None
            agent.update(replay.sample(config.batch_size), pair, step)
            step += 1
    agent.config = frozen.replace(num_updates=step)
    out.mkdir(parents=True, exist_ok=True)
    path = out / 'candidate.pt'
    extra = {'continual_from': str(deployed), 'bags': [str(b) for b in (*new_bags, *old_bags)],
             'transitions': len(replay), 'corrupt_rewards': corrupt_rewards}
    try:
        save_checkpoint(path, agent, step=step, extra=extra)
    except CheckpointError as error:
        raise TrainError(f'candidate diverged: {error}') from None
    candidate = Candidate(path, checkpoint_sha256(path), [str(b) for b in new_bags],
                          [str(b) for b in old_bags], len(replay), step - start - warmup,
                          warmup, time.perf_counter() - begin, seen.values, seen.source)
    card = {**{k: v for k, v in asdict(candidate).items() if k != 'path'}, 'path': str(path),
            'from': str(deployed), 'corrupt_rewards': corrupt_rewards,
            'representation': 'phi and psi frozen (the deployed context space)'}
    from zeus_ros.atomic_file import replace_text

    replace_text(out / 'card.json', json.dumps(card, indent=1) + '\n')
    log(f'continual: candidate {path} ({candidate.sha256[:12]}): {warmup} critic warm-up + '
        f'{candidate.updates} updates on {len(replay)} transitions ({len(new_bags)} new, '
        f'{len(old_bags)} old split(s)) in {candidate.seconds:.1f} s')
    return candidate


GATE_SAMPLES = 8192
"""Rehearsal steps whose policy context fits the actor's novelty gate."""


def _gate(agent: Any, rehearsal: Any, settings: ContinualSettings,
          log: Callable[[str], None]) -> None:
    """Gate the agent's actor (learning/gated_actor.py) on the rehearsal's train contexts."""
    import torch

    from zeus_ros.learning.gated_actor import fit_gate
    from zeus_ros.offline.data.replay import ReplayBuffer

    replay = ReplayBuffer(rehearsal, history=agent.config.k, seed=settings.seed,
                          pixels=agent.config.obs_kind == 'pixels')
    batch = replay.sample(GATE_SAMPLES).to(agent.device)
    with torch.no_grad():
        history, _ = agent.history_features(batch.hist_obs, batch.hist_action,
                                            batch.hist_reward, batch.hist_next_obs,
                                            batch.hist_mask)
        psi = agent.modules['psi'](history)
        context = agent.policy_context(psi, torch.zeros_like(psi))
    # One centroid per train value and history length: an episode's first k steps carry a
    # partial history whose psi sits apart from the settled one (it cannot know the context
    # yet), and there the deployed actor must act too.
    length = batch.hist_mask.sum(1).cpu().numpy()
    values = np.unique(batch.context.cpu().numpy().round(6), axis=0, return_inverse=True)[1]
    labels = values.ravel() * (agent.config.k + 1) + length
    centroids, scale, low, high = fit_gate(context.cpu().numpy(), labels)
    agent.gate_actor(centroids, scale, low, high)
    log(f'continual: actor gated on {len(centroids)} train contexts x history lengths (the '
        f'deployed actor below novelty {low:.2f}, the adapted one above {high:.2f}; '
        f'{len(labels)} rehearsal steps)')


def _anchor(settings: ContinualSettings, rehearsal: Path | None
            ) -> Callable[[Any], float] | None:
    """Per-episode behaviour-cloning weights (None: one weight for all).

    `bc_weight` on the rehearsal, `bc_weight_new` on the recording; None when `bc_weight_new`
    is negative.
    """
    if settings.bc_weight_new < 0:
        return None
    root = None if rehearsal is None else Path(rehearsal).resolve()

    def weight(episode: Any) -> float:
        source = Path(episode.source).resolve()
        kept = root is not None and (source == root or root in source.parents)
        return settings.bc_weight if kept else settings.bc_weight_new
    return weight


def agent_step(path: Path) -> int:
    """The update count stored in a checkpoint (0 when it has none)."""
    from zeus_ros.offline.training.train import checkpoint_step

    return checkpoint_step(path)


# ---------------------------------------------------------------------- round
def continual_round(deployed: Path | str, new_bags: Sequence[Path], splits: Sequence[Path],
                    out: Path | str, history: Path | str, settings: ContinualSettings, *,
                    corrupt_rewards: bool = False, log: Callable[[str], None] = print,
                    stop: Callable[[], bool] = lambda: False,
                    rehearsal: Path | None = None, start: Path | None = None,
                    round_number: int = 0,
                    on_decision: Callable[[Candidate, GateResult], dict[str, Any]] | None = None
                    ) -> RoundResult:
    """Train a candidate on the replay mix, gate it, and record the decision (no swap here).

    `rehearsal`: a bag (`rehearsal_bag`) added to the old data of the round. `start`: an
    earlier refused candidate to continue (`resume_from`); the gate still compares against
    `deployed`. `on_decision`: called once decided, before the history line; its fields join
    that line (a pixel deployment's refreshed student: continual_student.py).
    """
    old = [*replay_mix(splits, new_bags, settings), *([rehearsal] if rehearsal else [])]
    progress = RoundProgress(Path(out) / PROGRESS_FILE)
    candidate = train_candidate(start or deployed, new_bags, old, out, settings,
                                corrupt_rewards=corrupt_rewards, log=log, stop=stop,
                                readout_from=deployed, rehearsal=rehearsal, progress=progress)
    result = gate(deployed, candidate.path, candidate.seen, settings, progress)
    confirmation = None
    if result.deploy:  # held-out confirmation: the same decision on initial states not used
        confirmation = gate(deployed, candidate.path, candidate.seen,
                            replace(settings, eval_seed=settings.eval_seed + CONFIRM_SEED),
                            progress, 'confirmation')
        if not confirmation.deploy:
            result = replace(result, deploy=False, reason=(
                f'{result.reason}, but not confirmed on fresh initial states: '
                f'{confirmation.reason}'))
    from zeus_ros.offline.evaluation.records import checkpoint_sha256

    decided = {} if on_decision is None else on_decision(candidate, result)
    record = append_history(history, {
        'event': 'gate', 'round': round_number, 'candidate': str(candidate.path),
        'sha256': candidate.sha256,
        'deployed': str(deployed), 'deployed_sha256': checkpoint_sha256(deployed),
        'started_from': str(start or deployed),
        'new_bags': candidate.new_bags, 'old_bags': candidate.old_bags,
        'transitions': candidate.transitions, 'updates': candidate.updates,
        'warmup_updates': candidate.warmup_updates, 'train_s': round(candidate.seconds, 2),
        'corrupt_rewards': corrupt_rewards, 'seen_from': candidate.seen_from,
        'gain': result.gain, 'se': result.se,
        'required': result.required, 'deployed_seen': result.deployed_seen,
        'candidate_seen': result.candidate_seen, 'gate_s': round(result.seconds, 2),
        'values': result.values, 'eval_seed': settings.eval_seed,
        'confirmation': None if confirmation is None else {
            'eval_seed': settings.eval_seed + CONFIRM_SEED, 'gain': confirmation.gain,
            'se': confirmation.se, 'required': confirmation.required,
            'deploy': confirmation.deploy, 'reason': confirmation.reason,
            'gate_s': round(confirmation.seconds, 2), 'values': confirmation.values},
        'decision': 'deploy' if result.deploy else 'refuse',
        'reason': result.reason, **decided})
    log(f'continual: {"DEPLOY" if result.deploy else "REFUSE"} {candidate.path.name} '
        f'({candidate.sha256[:12]}): {result.summary()}; {result.reason}')
    return RoundResult(candidate, result, record)


def resume_from(result: RoundResult, settings: ContinualSettings, corrupt_rewards: bool = False
                ) -> Path | None:
    """Where the next round starts: this candidate, or None for the deployed checkpoint.

    Only a refused candidate that gained on the seen contexts, trained on true rewards.
    """
    if (result.gate.deploy or corrupt_rewards or not settings.resume_refused
            or not result.gate.gain > 0):
        return None
    return result.candidate.path


def run_round(deployed: Path | str, new_bags: Sequence[Path | str], splits: Sequence[Path | str],
              out: Path | str, history: Path | str, settings: ContinualSettings, *,
              first_checkpoint: Path | str, rehearsal_folder: Path | str,
              corrupt_rewards: bool = False, forced: bool = False,
              start: Path | str | None = None, log: Callable[[str], None] = print,
              stop: Callable[[], bool] = lambda: False, round_number: int = 0,
              teacher: Path | str | None = None) -> dict[str, Any]:
    """One round of the live trainer, as `zeus continual-round` runs it: a JSON-ready answer.

    The rehearsal recording of `first_checkpoint` (made once under `rehearsal_folder`, in a
    folder named by its sha256 and size), then
    `continual_round` from `start` (an earlier refused candidate; ignored when the file is
    gone) or `deployed`, and where the next round starts (`resume_from`; None when the round
    is `forced` past the gate). The answer holds what the node needs to swap and watch: the
    candidate's path and sha256, the gate's decision, figures and summary, `resume_from`, and
    the task's episode length (the live check's scale). Raises what `continual_round` raises
    (RoundStopped when `stop` answers True). Round `round_number` gates on evaluation seeds
    of its own (eval_seed + round_number x ROUND_SEED).

    A deployed pixel student (continual_student.py): the rehearsal, the training, the chain
    and the gate are its state teacher's (`teacher`, else the one its record names); the
    answer's candidate is the refreshed student (written when deployed or forced; None when
    refused) and `teacher_candidate` / `teacher` the state candidate / the deployed teacher.
    Raises StudentError (one line) for a pixel checkpoint without a state teacher.
    """
    from zeus_ros.offline.training.continual_student import refresh_on_swap, state_teacher

    settings = replace(settings, eval_seed=settings.eval_seed + round_number * ROUND_SEED)
    from zeus_ros.offline.evaluation.records import checkpoint_sha256

    state = state_teacher(deployed, teacher)
    first = state_teacher(first_checkpoint) if state is not None else None
    first_checkpoint = first or first_checkpoint
    # One rehearsal per first checkpoint and size under `rehearsal_folder`: a restarted
    # launch (a new recording folder beside it) finds it again instead of recording anew.
    folder = Path(rehearsal_folder)
    if settings.rehearsal_steps > 0 and Path(first_checkpoint).is_file():
        folder /= f'{checkpoint_sha256(first_checkpoint)[:12]}_{settings.rehearsal_steps}'
    rehearsal = rehearsal_bag(Path(first_checkpoint), folder, settings, log)
    begin = Path(start) if start is not None and Path(start).is_file() else None
    from sim_bridge.registry import task_class
    from zeus_ros.learning.inference import InferenceAgent

    task = InferenceAgent.from_checkpoint(deployed).task
    if state is not None:
        log(f'continual: pixel student {Path(deployed).name}: the round trains its state '
            f'teacher {state} on the recorded state vectors')
    result = continual_round(state or Path(deployed), [Path(b) for b in new_bags],
                             [Path(b) for b in splits], out, history, settings,
                             corrupt_rewards=corrupt_rewards, log=log, stop=stop,
                             rehearsal=rehearsal, start=begin, round_number=round_number,
                             on_decision=None if state is None else
                             refresh_on_swap(Path(deployed), task, forced))
    resume = None if forced else resume_from(result, settings, corrupt_rewards)
    gate_result = result.gate
    answer: dict[str, Any] = {
        'candidate': str(result.candidate.path), 'sha256': result.candidate.sha256,
        'deploy': gate_result.deploy, 'reason': gate_result.reason,
        'gain': gate_result.gain, 'se': gate_result.se, 'required': gate_result.required,
        'summary': gate_result.summary(),
        'resume_from': None if resume is None else str(resume),
        'episode_length': int(task_class(task).episode_length)}
    if state is not None:
        refreshed = result.record.get('refreshed_student')
        answer.update(candidate=refreshed, sha256=result.record.get('refreshed_sha256'),
                      teacher_candidate=str(result.candidate.path),
                      teacher_sha256=result.candidate.sha256, teacher=str(state))
    return answer
