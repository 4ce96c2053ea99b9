"""`zeus train`: bags -> replay buffer -> agent updates -> checkpoint, metrics CSV and plots.

Training reads bags only. The data decide the observation normalisation; the task registry
supplies the action bounds (bags carry applied actions, not the bounds). A run directory holds:
  checkpoint.pt (latest, what --resume continues), final.pt (end of the run), config.yaml
  (resolved), metrics.csv + losses.png, and with periodic evaluation eval.csv + eval_returns.png.
A non-finite loss or parameter (from a non-finite gradient) stops the run at that update with
NonFiniteError naming the last good checkpoint; no checkpoint with NaN/Inf is ever written.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import math
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np
from tqdm import tqdm
import yaml

from zeus_ros.cli_args import input_path
from zeus_ros.learning.config import (
    ZeusConfig,
    load_config,
    resolve_config,
    undeclared_defaults,
)
from zeus_ros.learning.errors import CheckpointError, ConfigError
from zeus_ros.learning.spec import PIXEL_SHAPE, AgentSpec
from zeus_ros.offline.evaluation.metrics import (
    MetricsLog,
    RunningMean,
    plot_grouped_lines,
    plot_metric_grid,
)
from zeus_ros.yaml_text import YamlTextError, load_yaml_text

__all__ = ['RUN_CONTROL_FIELDS', 'NonFiniteError', 'TrainError', 'TrainResult', 'apply_overrides',
           'build_spec', 'check_device', 'load_data', 'read_config', 'run_warnings', 'train']

CHECKPOINT = 'checkpoint.pt'
FINAL = 'final.pt'
RUN_CONTROL_FIELDS = frozenset({'num_updates', 'eval_interval', 'eval_episodes',
                                'checkpoint_interval', 'log_interval', 'device'})
"""Config fields a resumed run may change: they steer the run, not the networks or losses."""
LATER_FIELD = 'representation_frozen_from'
"""A config field that acts only from its update on: a resume before it may change it."""
SHOWN_LOSSES = ('loss/critic', 'loss/actor', 'loss/context', 'loss/dynamics', 'loss/reward',
                'loss/osi', 'loss/reconstruction')
"""Losses shown on the progress bar (those the method has)."""


class TrainError(Exception):
    """A training run cannot start or continue (bad data, task or resume mismatch)."""


class NonFiniteError(TrainError):
    """An update produced a NaN/Inf loss or parameter: the run stopped, nothing was saved after."""


def _nonfinite_losses(row: dict[str, float]) -> list[str]:
    """The metrics of one update that are NaN or infinite, as 'name=value'."""
    return [f'{key}={value}' for key, value in row.items()
            if isinstance(value, float) and not math.isfinite(value)]


def _nonfinite_modules(agent: Any) -> list[str]:
    """Modules whose parameters hold NaN/Inf (one fused sum per module: ~0.3 ms an update).

    After an optimizer step a NaN or Inf gradient always shows up in the parameters, so this
    catches a non-finite gradient in the update that produced it.
    """
    import torch

    bad = [name for name, module in agent.modules.items()
           if (params := [p.detach().sum() for p in module.parameters()])
           and not bool(torch.isfinite(torch.stack(params).sum()))]
    if not bool(torch.isfinite(agent.log_alpha.detach()).all()):
        bad.append('log_alpha')
    return bad


@dataclass
class TrainResult:
    """What one `train` call did."""

    out: Path
    checkpoint: Path
    start_step: int
    step: int
    seconds: float
    log: list[dict[str, Any]] = field(default_factory=list)
    evals: list[dict[str, Any]] = field(default_factory=list)

    @property
    def updates_per_s(self) -> float:
        """Updates done by this call per wall-clock second."""
        return (self.step - self.start_step) / max(self.seconds, 1e-9)


def apply_overrides(config: ZeusConfig, *, method: str | None = None,
                    updates: int | None = None, seed: int | None = None,
                    device: str | None = None) -> ZeusConfig:
    """CLI flags win over the config file (validated like the file)."""
    changes: dict[str, Any] = {}
    for name, value in (('method', method), ('num_updates', updates), ('seed', seed),
                        ('device', device)):
        if value is not None:
            changes[name] = value
    return config.replace(**changes) if changes else config


SIZE_KEYS = ('method', 'k', 'context_dim', 'feature_dim', 'hidden_dim', 'batch_size',
             'num_updates')
"""What a training config must set itself (or take from `base:`): the networks and the budget.

Left out, the dataclass defaults are the paper's (1024-wide networks, a million updates): a
silent multi-day run on a CPU."""


def read_config(path: Path, flag: str = '--config') -> ZeusConfig:
    """load_config, but a binary or empty file is a ConfigError naming the flag, not a default.

    An empty config would silently train with every default: refused, so a truncated or
    wrongly named file cannot pass for a deliberate choice. A relative path not in the working
    directory is looked up in the package share (params/train/... from any folder).
    """
    try:
        path = input_path(path, flag)
        data = load_yaml_text(path)
    except OSError as error:
        raise ConfigError(f'{flag} {path}: cannot read it ({error.strerror})') from None
    except YamlTextError as error:  # a ValueError too: caught first, so the file is named
        hint = ('; expected a YAML training config such as params/train/state_cpu.yaml'
                if error.binary else '')
        raise ConfigError(f'{flag} {path}: {error}{hint}') from None
    except ValueError as error:
        raise ConfigError(str(error)) from None
    if data is None:
        raise ConfigError(f'{flag} {path}: the file is empty (no keys); refusing to train with '
                          'every default by accident: start from params/train/state_cpu.yaml')
    if not isinstance(data, dict):
        raise ConfigError(f'{flag} {path}: expected a mapping of config keys, got a '
                          f'{type(data).__name__}')
    missing = [key for key in SIZE_KEYS if key not in data]
    if missing and 'base' not in data:
        raise ConfigError(f'{flag} {path}: no {", ".join(missing)}: a config sets the size of '
                          'its run or names a base to take it from (base: state_cpu.yaml, '
                          "relative to the file); refusing the paper's GPU-sized defaults")
    return load_config(path)


def check_device(device: str, flag: str = '--device') -> None:
    """Refuse a device this machine's torch cannot use, before any data is read."""
    import torch

    try:
        wanted = torch.device(device) if device != 'auto' else None
    except (RuntimeError, ValueError) as error:
        raise ConfigError(f'{flag} {device}: not a device ({error}); use auto, cpu or '
                          'cuda[:N]') from None
    if wanted is None or wanted.type == 'cpu':
        return
    if wanted.type != 'cuda':
        raise ConfigError(f'{flag} {device}: only auto, cpu and cuda[:N] are supported')
    if not torch.cuda.is_available():
        why = ('this torch build has no CUDA support' if torch.version.cuda is None
               else 'no CUDA device is visible')
        raise ConfigError(f'{flag} {device}: {why} (torch {torch.__version__}); use --device '
                          'cpu or auto')
    if wanted.index is not None and wanted.index >= torch.cuda.device_count():
        raise ConfigError(f'{flag} {device}: only {torch.cuda.device_count()} CUDA device(s) '
                          'are visible')


def build_spec(dataset: Any, replay: Any, config: ZeusConfig) -> AgentSpec:
    """The agent's task side: shapes and normalisation from the data, bounds from the registry.

    The action bounds come from the task registry because bags carry applied actions only.
    """
    from sim_bridge.registry import make_task

    try:
        task = make_task(dataset.task)
    except (KeyError, ValueError) as error:
        raise TrainError(f'bags name task {dataset.task!r}, which the task registry does not '
                         f'know ({error}); record with a registered task, or pass the file that '
                         'declares it with --task-file') from None
    try:
        low, high = task.action_bounds
        if len(low) != dataset.action_dim:
            raise TrainError(f'bags hold {dataset.action_dim}-d actions but {dataset.task} has '
                             f'{len(low)} actuators: the bags were not recorded on this task')
        pixels = config.obs_kind == 'pixels'
        return AgentSpec(
            task=dataset.task, context_names=dataset.context_names, obs_kind=config.obs_kind,
            obs_shape=PIXEL_SHAPE if pixels else (dataset.obs_dim,),
            action_dim=dataset.action_dim, action_low=low, action_high=high,
            obs_mean=None if pixels else replay.obs_mean,
            obs_std=None if pixels else replay.obs_std)
    finally:
        task.close()


def _report_cut_bags(bags: Sequence[str], log: Callable[[str], None]) -> None:
    """Say which bags a crash cut short: their round may hold fewer steps than it asked for."""
    from zeus_ros.bags.recover import bag_state

    cut = [f'{bag} ({state})' for bag in bags
           if (state := bag_state(Path(bag))) in ('recovered', 'unfinished', 'provisional')
           and not any(Path(bag).parent.glob(f'{Path(bag).name}_rest*'))]  # loop completed it
    if cut:
        log(f'train: WARNING: {len(cut)} bag(s) were cut short by a crash: {", ".join(cut)}; '
            'their collection stopped early, so their round may hold fewer steps than it '
            'asked for (`zeus loop --resume` collects what a round lacks)')


def _config_differences(stored: ZeusConfig, wanted: ZeusConfig, step: int) -> list[str]:
    """Fields that would make a resume at `step` differ from one run with `wanted` from 0.

    `representation_frozen_from` acts only from its update on, so a resume that has reached
    neither the stored nor the wanted value may change it (a frozen-from-10k variant continues
    a finished 10k run). `alpha_psi` weighs eq. 1's context loss, so a method without it
    (methods.py) may change it: a no_context run trained while `alpha_psi: auto` meant 1.0
    continues unchanged now that it means 0.
    """
    from zeus_ros.learning.methods import method_objective

    old, new = stored.to_dict(), wanted.to_dict()
    unread = {key for key in ('alpha_psi',) if not method_objective(stored.method).reads(key)}

    def not_reached(value: int) -> bool:
        return value == 0 or value >= step

    return [f'{key}: checkpoint {old[key]!r}, now {new[key]!r}' for key in old
            if key not in RUN_CONTROL_FIELDS and key not in unread and old[key] != new[key]
            and not (key == LATER_FIELD and not_reached(old[key]) and not_reached(new[key]))]


def run_warnings(config: ZeusConfig, task: str, transitions: int) -> list[str]:
    """What this run guesses or lacks, one line each: it goes ahead, but not silently.

    An `alpha_psi: auto` the task's family does not declare (learning/config.py), and fewer
    transitions than `seed_steps`, the uniform-random steps the paper collects before its
    first update: a run on less fits a few hundred steps and says nothing of the method.
    """
    warnings = [note] if (note := undeclared_defaults(config, task)) else []
    if transitions < config.seed_steps:
        warnings.append(f'the bags hold {transitions} transitions, fewer than seed_steps '
                        f'{config.seed_steps} (the random steps the paper collects before '
                        'learning starts): expect a policy fitted to these few; record more '
                        f'(zeus collect --steps {config.seed_steps}) or --set '
                        f'seed_steps={transitions} to say this is meant')
    return warnings


def load_data(bags: Sequence[str | Path], config: ZeusConfig, task: str | None,
              device: Any, seed: int, namespace: str = '', strict: bool = False
              ) -> tuple[Any, Any]:
    """(dataset, replay buffer) of `bags` for `config`; TrainError on another task or no frames."""
    from zeus_ros.offline.data.ingest import ingest_bags
    from zeus_ros.offline.data.replay import ReplayBuffer

    dataset = ingest_bags(list(bags), namespace=namespace, strict=strict)
    if task is not None and dataset.task != task:
        raise TrainError(f'--task {task} but the bags hold {dataset.task!r} '
                         f'({", ".join(dataset.report.bags)})')
    if config.obs_kind == 'pixels' and not dataset.has_frames:
        raise TrainError('the config trains on pixels but the bags carry no frames: '
                         'collect with --pixels or use a state config')
    replay = ReplayBuffer(dataset, history=config.k, pixels=config.obs_kind == 'pixels',
                          device=device, seed=seed, model_horizon=config.model_horizon)
    if len(replay) < config.batch_size:
        raise TrainError(f'the bags hold {len(replay)} transitions, fewer than one batch '
                         f'({config.batch_size}); record more steps')
    return dataset, replay


def _start(out: Path, config: ZeusConfig, dataset: Any, replay: Any, resume: bool
           ) -> tuple[Any, int]:
    """A fresh agent, or the one in out/checkpoint.pt after checking it fits this run."""
    from zeus_ros.learning.agent import make_agent
    from zeus_ros.learning.checkpoint import load_checkpoint
    from zeus_ros.learning.utils import set_seed_everywhere

    path = out / CHECKPOINT
    if not resume:
        if path.exists():
            raise TrainError(f'{out} already holds a run ({path}); pass --resume to continue '
                             'it or choose another --out')
        return make_agent(config, build_spec(dataset, replay, config)), 0
    if not path.is_file():
        raise TrainError(f'--resume: no checkpoint at {path}; start without --resume')
    try:
        loaded = load_checkpoint(path, map_location=config.device, expect_task=dataset.task,
                                 expect_obs_kind=config.obs_kind)
    except CheckpointError as error:
        raise TrainError(f'--resume: {error}') from None
    if loaded.deploy:
        raise TrainError(f'--resume: {path} is a deployment export (acting networks only, no '
                         "critics or optimizers); resume from the run's checkpoint.pt instead")
    wanted = resolve_config(config, dataset.task)
    diffs = _config_differences(loaded.config, wanted, loaded.step)
    if diffs:
        raise TrainError(f'--resume: {path} was trained with another config; '
                         f'differences: {"; ".join(diffs)}. Resume with the same config and '
                         f'flags (only {", ".join(sorted(RUN_CONTROL_FIELDS))} may change), '
                         'or train into a new --out')
    if loaded.spec.obs_shape[0] != (PIXEL_SHAPE[0] if config.obs_kind == 'pixels'
                                    else dataset.obs_dim):
        raise TrainError(f'--resume: {path} expects observations of shape '
                         f'{loaded.spec.obs_shape}, the bags hold {dataset.obs_dim}-d states')
    agent = loaded.agent
    run = {name: getattr(wanted, name) for name in (*RUN_CONTROL_FIELDS, LATER_FIELD)}
    agent.config = loaded.config.replace(**run)
    set_seed_everywhere(wanted.seed + loaded.step)
    return agent, loaded.step


def train(bags: Sequence[str | Path], config: ZeusConfig, out: str | Path, *,
          task: str | None = None, resume: bool = False, evaluate: bool = True,
          progress: bool = True, log: Callable[[str], None] = print,
          namespace: str = '', strict: bool = False, readout_steps: int = 0) -> TrainResult:
    """Train (or continue training) an agent on the transitions in `bags`.

    `namespace`: read /<namespace>/zeus/... topics (`ros2 bag record` of a namespaced system).
    `strict`: refuse bags with any issue (gaps, NaN/Inf, wrong lengths) instead of dropping
    the affected transitions.

    Runs until `config.num_updates` updates in total (a resumed run counts from its
    checkpoint's step). Checkpoints every `checkpoint_interval` updates and at the end; a
    Ctrl-C also saves, so no finished update is lost.

    `readout_steps` > 0: final.pt also carries the context read-out and novelty monitor,
    fitted as `zeus export` fits them, so it deploys with the estimate-vs-truth view.
    """
    from zeus_ros.learning.checkpoint import save_checkpoint
    from zeus_ros.learning.utils import resolve_device

    out = Path(out)
    device = resolve_device(config.device)
    config = config.replace(device=str(device))
    resume_step = checkpoint_step(out / CHECKPOINT) if resume else 0
    dataset, replay = load_data(bags, config, task, device, config.seed + resume_step,
                                 namespace, strict)
    agent, start = _start(out, config, dataset, replay, resume)
    cfg = agent.config
    from sim_bridge.registry import is_simulated

    if evaluate and not is_simulated(dataset.task):
        log(f'train: {dataset.task} is a robot (no simulator here): no periodic evaluation')
        evaluate = False
    out.mkdir(parents=True, exist_ok=True)
    (out / 'config.yaml').write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))
    log(f'train: {dataset.task}, method {cfg.method}, {len(replay)} transitions in '
        f'{replay.num_episodes} episodes from {len(dataset.report.bags)} bag(s); '
        f'updates {start} -> {cfg.num_updates} on {device}')
    _report_cut_bags(dataset.report.bags, log)
    for warning in run_warnings(config, dataset.task, len(replay)):
        log(f'train: warning: {warning}')
    metrics = MetricsLog.resume(out / 'metrics.csv', up_to_step=start) if resume \
        else MetricsLog(out / 'metrics.csv')
    evals = MetricsLog.resume(out / 'eval.csv', up_to_step=start) if resume \
        else MetricsLog(out / 'eval.csv')
    needs_pair = agent.objective.needs_pair(cfg)
    extra = {'bags': [str(b) for b in dataset.report.bags], 'transitions': len(replay),
             **provenance()}
    window = RunningMean()
    step = start
    begin = window_start = time.perf_counter()
    # A resumed run's wall time continues from its last logged row (loop rounds add up).
    time_before = float(metrics.rows[-1].get('time_s') or 0.0) if metrics.rows else 0.0
    window_steps = 0

    last_good = (out / CHECKPOINT, start) if resume else None

    def save(name: str = CHECKPOINT) -> Path:
        nonlocal last_good
        try:
            path = save_checkpoint(out / name, agent, step=step, extra=extra)
        except CheckpointError as error:  # non-finite weights: the check below missed nothing
            raise NonFiniteError(f'update {step}: {error}; {_last_good(last_good)}') from None
        if name == CHECKPOINT:
            last_good = (path, step)
        return path

    bar = tqdm(total=cfg.num_updates, initial=start, unit='upd', desc='train',
               disable=not progress, dynamic_ncols=True)
    try:
        while step < cfg.num_updates:
            batch = replay.sample(cfg.batch_size)
            pair = replay.sample(cfg.batch_size) if needs_pair else None
            losses = agent.update(batch, pair, step)
            bad = _nonfinite_losses(losses)
            modules = _nonfinite_modules(agent)
            if bad or modules:
                metrics.flush()
                what = ', '.join(bad) if bad else 'losses finite'
                params = (f'; non-finite parameters in {", ".join(modules)} (a NaN/Inf '
                          'gradient)' if modules else '')
                raise NonFiniteError(
                    f'update {step + 1}: {what}{params}. Training stopped; nothing of this '
                    f'update was saved; {_last_good(last_good)}. Check the data (zeus ingest '
                    '--strict) and the learning rates')
            window.add(losses)
            step += 1
            window_steps += 1
            bar.update(1)
            if step % cfg.log_interval == 0 or step == cfg.num_updates:
                now = time.perf_counter()
                row = {'step': step, 'time_s': round(time_before + now - begin, 3),
                       'updates_per_s': window_steps / max(now - window_start, 1e-9),
                       **window.pop()}
                window_start, window_steps = now, 0
                metrics.append(row)
                metrics.flush()
                bar.set_postfix({key.split('/')[1]: f'{row[key]:.3g}' for key in SHOWN_LOSSES
                                 if key in row})
            if evaluate and step % cfg.eval_interval == 0:
                rows = _evaluate(agent, dataset.task, cfg, step)
                for row in rows:
                    evals.append(row)
                evals.flush()
                mean = float(np.mean([row['return'] for row in rows]))
                bar.write(f'eval @ {step}: mean return {mean:.1f} over {len(rows)} episodes')
                _plot(out, metrics, evals)
                window_start = time.perf_counter()  # updates/s measures updates only
            if step % cfg.checkpoint_interval == 0:
                save()
    except KeyboardInterrupt:
        bar.close()
        save()
        metrics.flush()
        log(f'train: interrupted at update {step}; saved {out / CHECKPOINT} (use --resume)')
        raise
    bar.close()
    seconds = time.perf_counter() - begin  # the updates' time: the read-out is timed apart
    save()
    extra.update(_readout_extra(agent, readout_steps, log))
    final = save(FINAL)
    _plot(out, metrics, evals)
    result = TrainResult(out, final, start, step, seconds, metrics.rows, evals.rows)
    log(f'train: {step - start} updates in {seconds:.1f} s ({result.updates_per_s:.1f}/s); '
        f'checkpoints {out / CHECKPOINT}, {final}; metrics {metrics.path}')
    return result


def _readout_extra(agent: Any, steps: int, log: Callable[[str], None]) -> dict[str, Any]:
    """The read-out and novelty monitor for final.pt's extra ({} where none can be fitted)."""
    from zeus_ros.learning.readout import EXTRA_KEY, NOVELTY_KEY
    from zeus_ros.offline.evaluation.calibrate import deployment_readout

    begin = time.perf_counter()
    try:
        fitted = deployment_readout(agent, steps)
    except ValueError as error:  # final.pt still deploys, showing raw psi
        log(f'train: warning: no context read-out in {FINAL} ({error}); fit one with zeus '
            'export --readout-steps')
        return {}
    if fitted is None:
        return {}
    log(f'train: context read-out and novelty monitor fitted on {steps} steps of the policy in '
        f'{time.perf_counter() - begin:.1f} s (as zeus export does); {FINAL} deploys with them')
    return {EXTRA_KEY: fitted[0].to_dict(), NOVELTY_KEY: fitted[1].to_dict()}


def _last_good(last: tuple[Path, int] | None) -> str:
    """Where the run can be continued from, for error messages."""
    if last is None:
        return 'no checkpoint was saved before it'
    return f'the last good checkpoint is {last[0]} (update {last[1]})'


def provenance() -> dict[str, str | None]:
    """The command line and source commit a checkpoint came from (for its card)."""
    import shlex
    import subprocess

    command = shlex.join([Path(sys.argv[0]).name, *sys.argv[1:]])
    try:
        commit = subprocess.run(['git', 'rev-parse', 'HEAD'], capture_output=True, text=True,
                                cwd=Path(__file__).resolve().parent, timeout=5, check=True)
        sha: str | None = commit.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        sha = None
    return {'command': command, 'code_commit': sha}


def checkpoint_step(path: Path) -> int:
    """Update count of an existing checkpoint (0 when absent): seeds the resumed sampler."""
    if not path.is_file():
        return 0
    import torch

    try:
        return int(torch.load(path, map_location='cpu', weights_only=True).get('step', 0))
    except Exception:  # load_checkpoint reports a broken file with a clear message later
        return 0


def _evaluate(agent: Any, task: str, cfg: ZeusConfig, step: int) -> list[dict[str, Any]]:
    """Periodic evaluation: deterministic episodes at train-split context values."""
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts, split_values

    values = split_values(task, 'train')
    picks = np.linspace(0, len(values) - 1, min(cfg.eval_episodes, len(values)))
    chosen = [values[round(i)] for i in picks]
    rows = evaluate_contexts(InferenceAgent(agent), chosen, episodes=1,
                             seed=cfg.seed + step, progress=False)
    return [{'step': step, **row} for row in rows]


def _plot(out: Path, metrics: MetricsLog, evals: MetricsLog) -> None:
    keys = [key for key in dict.fromkeys(k for row in metrics.rows for k in row)
            if key.startswith(('loss/', 'train/')) or key == 'updates_per_s']
    plot_metric_grid(metrics.rows, keys, out / 'losses.png', title=f'training: {out.name}')
    if evals.rows:
        group = next(key for key in evals.rows[0] if key.startswith('context/'))
        plot_grouped_lines(evals.rows, x='step', y='return', group=group,
                           path=out / 'eval_returns.png', ylabel='episode return',
                           title='evaluation return per context value')
