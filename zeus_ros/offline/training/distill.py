"""A pixel student distilled from a state teacher in DAgger rounds (cli/distill.py: the command).

    zeus distill --task Cheetah-Bias-v0 --teacher checkpoints/cheetah_bias_v0/zeus.pt
        --out runs/pixels_student/s0

Why: pixel RL does not fit this CPU (0.083 ZeUS updates/s), but the zoo's state agents already
adapt. Following privileged-teacher distillation (Chen et al. 2019, "Learning by Cheating"), RMA
(Kumar et al. 2021: an adaptation module regresses the teacher's latent context from the
history) and DAgger (Ross et al. 2011: the student acts, the teacher labels every visited step),
the student is a regular pixel ZeusAgent (conv phi on stacked frames, psi over the last k
transitions, actor on [phi(o), psi]) trained by regression instead of RL:

    loss = MSE(a_student, a_teacher) + psi_weight * MSE(psi_student, psi_teacher) / var(psi_t)

on the same step; the teacher sees the state and its own state history. Two heads: `own` (the
student learns its own psi and actor on [phi(o), psi]) or `teacher` (RMA's reuse of the base
policy: the student's phi is regressed on the teacher's state features phi_T(s), with the
teacher's psi and actor copied and frozen on top, so beyond the training range the student acts
as the teacher's psi and actor extrapolate; loss + feature_weight * MSE(phi(o), phi_T(s))).
Frames get one random
shift per window (DrQ, Kostrikov et al. 2020). Round 0: the teacher acts with a little noise;
later rounds: the student acts. The result is a deployment checkpoint that every consumer of
pixel checkpoints loads unchanged (InferenceAgent, zeus eval, zeus adaptation, the live nodes).
Its `method` names the architecture (the teacher's psi method, or `no_context` for the student
without psi); `extra['distill']` says how it was trained.
"""

from __future__ import annotations

import csv
from dataclasses import asdict
import hashlib
from pathlib import Path
import time
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812
from tqdm import tqdm

from zeus_ros.learning.augment import random_shift
from zeus_ros.learning.config import ZeusConfig
from zeus_ros.learning.context import HistoryFeatures
from zeus_ros.learning.errors import ConfigError
from zeus_ros.offline.training.distill_data import (
    EpisodeStore,
    WindowBatch,
    collect_round,
    save_episodes,
)
from zeus_ros.offline.training.distill_resume import (
    RESUME_FILE,
    ResumePoint,
    clear_resume,
    load_resume,
    round_data_path,
    save_resume,
)
from zeus_ros.offline.training.distill_settings import (
    DEFAULT_CONFIG,
    HEADS,
    TEACHER_HEAD_WITHOUT_PSI,
    DistillSettings,
)

__all__ = ['DEFAULT_CONFIG', 'HEADS', 'DistillSettings', 'distill', 'distill_loss',
           'make_student', 'random_shift']

SCHEDULE = 'switch:train:every_episodes=1'
"""One train value per episode, in turn, as `zeus loop` collects."""


def _fail(message: str) -> ConfigError:
    return ConfigError(message)


def make_student(config: ZeusConfig, teacher: Any, task: str, *, no_context: bool = False,
                 head: str = 'own') -> Any:
    """A fresh pixel ZeusAgent whose psi has the teacher's k and context size.

    head 'teacher': the teacher's own networks (its config) with config's conv phi in front,
    phi sized to the teacher's features; psi and actor are copies of the teacher's, frozen.
    """
    from zeus_ros.learning.agent import make_agent
    from zeus_ros.learning.spec import PIXEL_SHAPE, AgentSpec

    if config.obs_kind != 'pixels':
        raise _fail(f"the student sees frames: the config has obs_kind '{config.obs_kind}'; "
                    'use a pixel config (params/train/pixels_student.yaml)')
    if teacher.obs_kind != 'state':
        raise _fail(f'the teacher must be a state checkpoint (it sees the state); this one '
                    f'has obs_kind {teacher.obs_kind!r}')
    if teacher.task != task:
        raise _fail(f"the teacher was trained on '{teacher.task}', not '{task}'")
    spec = teacher.agent.spec
    pixel_spec = AgentSpec(task=task, context_names=spec.context_names, obs_kind='pixels',
                           obs_shape=PIXEL_SHAPE, action_dim=spec.action_dim,
                           action_low=spec.action_low, action_high=spec.action_high)
    psi_teacher = 'psi' in teacher.agent.modules
    if head == 'teacher':
        if no_context:
            raise _fail(TEACHER_HEAD_WITHOUT_PSI)
        return _teacher_head_student(config, teacher, pixel_spec, psi_teacher)
    if no_context or not psi_teacher:
        changes: dict[str, Any] = {'method': 'no_context'}
    else:
        changes = {'method': teacher.method, 'k': teacher.k, 'context_dim': teacher.context_dim}
    return make_agent(config.replace(context_norm='none', **changes), pixel_spec,
                      device='cpu')


def _teacher_head_student(config: ZeusConfig, teacher: Any, pixel_spec: Any,
                          psi_teacher: bool) -> Any:
    from zeus_ros.learning.agent import make_agent

    if not psi_teacher:
        raise _fail(f'the teacher head needs a teacher with psi; this one is {teacher.method!r}')
    own = teacher.agent.config
    student = make_agent(own.replace(
        obs_kind='pixels', num_conv_layers=config.num_conv_layers,
        num_filters=config.num_filters, batch_size=config.batch_size,
        encoder_lr=config.encoder_lr, augment_shift=config.augment_shift, seed=config.seed,
        device='cpu'), pixel_spec, device='cpu')
    for name in ('psi', 'actor', 'context_norm'):
        if name in teacher.agent.modules:
            student.modules[name].load_state_dict(teacher.agent.modules[name].state_dict())
            student.modules[name].requires_grad_(False)
    return student


def distill_loss(student: Any, batch: WindowBatch, k: int, psi_scale: torch.Tensor,
                 psi_weight: float, teacher_feat: torch.Tensor | None = None,
                 feature_weight: float = 0.0) -> tuple[torch.Tensor, dict[str, float]]:
    """Action MSE (in [-1, 1] units) + weighted psi MSE over every labelled position.

    Each frame stack is encoded once; position p's history is the k positions before it
    (AgentPolicy's: transition j = (o_j, a applied at j + 1, r at j + 1, o_{j + 1})).
    With `teacher_feat` (E, k + L, F), the teacher's phi_T(s) of every position: plus
    feature_weight * MSE(phi(o), phi_T(s)) over the valid positions.
    """
    m = student.modules
    e, n = batch.valid.shape
    window = n - k
    feat = m['encoder'](batch.stacks.flatten(0, 1)).view(e, n, -1)
    pos = torch.arange(window)[:, None] + torch.arange(k)[None]  # (L, k): slots j
    current = feat[:, k:].reshape(e * window, -1)
    if 'psi' in m:
        history = HistoryFeatures(
            feat=feat[:, pos].flatten(0, 1), next_feat=feat[:, pos + 1].flatten(0, 1),
            action=student.normalize_action(batch.applied[:, pos + 1]).flatten(0, 1),
            reward=batch.reward[:, pos + 1].flatten(0, 1).unsqueeze(-1),
            mask=batch.valid[:, pos].flatten(0, 1))
        psi = m['psi'](history)
        context = student.policy_context(psi)
    else:
        psi = context = current.new_zeros(e * window, 0)
    action = torch.tanh(m['actor'](torch.cat([current, context], dim=-1)).mu)
    target = student.normalize_action(batch.teacher_action.flatten(0, 1))
    action_loss = F.mse_loss(action, target)
    metrics = {'loss/action': float(action_loss.detach())}
    total = action_loss
    if psi.shape[-1]:
        psi_loss = (((psi - batch.teacher_psi.flatten(0, 1)) / psi_scale) ** 2).mean()
        total = total + psi_weight * psi_loss
        metrics['loss/psi'] = float(psi_loss.detach())
    if teacher_feat is not None:
        mask = batch.valid.unsqueeze(-1).float()
        feature_loss = (((feat - teacher_feat) ** 2) * mask).sum() / (
            mask.sum() * feat.shape[-1]).clamp(min=1.0)
        total = total + feature_weight * feature_loss
        metrics['loss/feature'] = float(feature_loss.detach())
    return total, metrics


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def distill(task: str, teacher_path: Path, config: ZeusConfig, settings: DistillSettings,
            out: Path, *, data_cache: Path | None = None, progress: bool = True,
            resume: bool = False) -> Path:
    """Run the DAgger rounds; write out/student.pt (deployment export) and out/rounds.csv.

    After every round a resume point is written (distill_resume.py); `resume` continues a
    stopped run from it. Without `resume`, an `out` holding a stopped run is refused.
    """
    from zeus_ros.learning.checkpoint import export_for_deployment, save_checkpoint
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.rollout import parse_schedule

    teacher = InferenceAgent.from_checkpoint(teacher_path)
    student = make_student(config, teacher, task, no_context=settings.no_context,
                           head=settings.head)
    k = student.config.k
    m = student.modules
    params = [{'params': m['encoder'].parameters(), 'lr': config.encoder_lr}]
    if settings.head == 'own':
        params.append({'params': m['actor'].parameters(), 'lr': config.actor_lr})
        if 'psi' in m:
            params.append({'params': m['psi'].parameters(), 'lr': config.context_lr})
    elif settings.tune_head > 0:
        for name, lr in (('actor', config.actor_lr), ('psi', config.context_lr)):
            m[name].requires_grad_(True)
            params.append({'params': m[name].parameters(), 'lr': lr * settings.tune_head})
    teacher_phi = teacher.agent.modules['encoder'] if settings.head == 'teacher' else None
    optimizer = torch.optim.Adam(params)
    store = EpisodeStore(settings.max_steps)
    rng = np.random.default_rng(config.seed)
    schedule = parse_schedule(SCHEDULE)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    windows = max(1, config.batch_size // settings.window)
    step = first_round = 0
    teacher_sha256 = _sha256(teacher_path)
    fingerprint = {'task': task, 'teacher_sha256': teacher_sha256, **asdict(settings),
                   **{f'config.{key}': value for key, value in config.to_dict().items()},
                   'data_cache': None if data_cache is None else str(data_cache)}
    if resume:
        point = load_resume(out, fingerprint, store, data_cache)
        for name, state in point.modules.items():
            m[name].load_state_dict(state)
        optimizer.load_state_dict(point.optimizer)
        rng.bit_generator.state = point.numpy_rng
        torch.set_rng_state(point.torch_rng)
        rows, step, first_round = point.rows, point.step, point.round_ + 1
        print(f'resumed after round {point.round_} ({step} updates)', flush=True)
    elif (out / RESUME_FILE).is_file():
        raise ConfigError(f'{out} holds a stopped run ({out / RESUME_FILE}): pass --resume to '
                          'continue it, or give another --out')
    for round_ in range(first_round, settings.rounds):
        started = time.perf_counter()
        cached = round_ == 0 and data_cache is not None and data_cache.is_file()
        returns: list[float] = []
        if cached:
            store.load(data_cache)
        else:
            acting = None if round_ == 0 else InferenceAgent(student, reuse_features=True)
            episodes, returns = collect_round(
                task, schedule, teacher, acting,
                settings.first_steps if round_ == 0 else settings.round_steps,
                seed=config.seed * 1000 + round_ + (0 if data_cache is None else 10**6),
                noise=settings.noise, progress=progress)
            for episode in episodes:
                store.add(episode)
            if round_ == 0 and data_cache is not None:
                store.save(data_cache)
            elif episodes:
                save_episodes(round_data_path(out, round_), episodes)
        if not store.episodes:
            raise ValueError('no complete episode collected: give more steps per round')
        collect_s = time.perf_counter() - started
        psi_scale = torch.from_numpy(store.psi_scale())
        if teacher_phi is not None and store.episodes[0].state.shape[-1] == 0:
            raise ValueError(f'the round-0 data {data_cache} holds no states (saved before '
                             'they were stored): the teacher head needs them; delete it or '
                             'give another --data-cache')
        started = time.perf_counter()
        sums: dict[str, float] = {}
        for _ in tqdm(range(settings.updates), desc=f'round {round_}', unit='upd',
                      disable=not progress, leave=False):
            batch = store.sample(rng, windows, settings.window, k)
            batch.stacks = random_shift(batch.stacks, settings.shift, rng)
            target = None
            if teacher_phi is not None:
                with torch.no_grad():
                    target = teacher_phi(batch.state.flatten(0, 1)).view(
                        *batch.state.shape[:2], -1)
            loss, metrics = distill_loss(student, batch, k, psi_scale, settings.psi_weight,
                                         target, settings.feature_weight)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            step += 1
            for name, value in metrics.items():
                sums[name] = sums.get(name, 0.0) + value
        train_s = time.perf_counter() - started
        row = {'round': round_, 'actor': 'teacher' if round_ == 0 else 'student',
               'episodes_stored': len(store.episodes), 'updates': step,
               'return_acting': float(np.mean(returns)) if returns else float('nan'),
               'collect_s': round(collect_s, 1), 'train_s': round(train_s, 1),
               **{name: value / max(settings.updates, 1) for name, value in sums.items()}}
        rows.append(row)
        print(f'round {round_}: ' + ', '.join(
            f'{key} {value:.4g}' if isinstance(value, float) else f'{key} {value}'
            for key, value in row.items() if key != 'round'), flush=True)
        save_resume(out, ResumePoint(
            round_=round_, step=step, rows=rows, optimizer=optimizer.state_dict(),
            modules={name: module.state_dict() for name, module in m.items()},
            numpy_rng=dict(rng.bit_generator.state), torch_rng=torch.get_rng_state(),
            fingerprint=fingerprint))
    _write_rows(out / 'rounds.csv', rows)
    extra = {'distill': {'teacher': str(teacher_path), 'teacher_sha256': teacher_sha256,
                         'teacher_method': teacher.method, 'settings': asdict(settings),
                         'schedule': SCHEDULE, 'rounds': rows}}
    full = save_checkpoint(out / 'student_full.pt', student, step=step, extra=extra)
    target = export_for_deployment(full, out / 'student.pt')
    full.unlink()
    clear_resume(out)
    return target


def _write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    names = sorted({key for row in rows for key in row}, key=lambda key: (
        list(rows[0]).index(key) if key in rows[0] else len(rows[0])))
    with path.open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=names)
        writer.writeheader()
        writer.writerows(rows)
