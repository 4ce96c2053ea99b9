"""Checkpoints: state_dicts plus plain data, validated on load with errors that name the file.

Layout (a dict of tensors and plain Python data, loadable with torch.load(weights_only=True)):
  format_version, method, obs_kind, task, k, aggregation, context_dim, spec (AgentSpec.to_dict),
  config (ZeusConfig.to_dict, resolved), step, extra (plain data), state (ZeusAgent.state_dict).
A deployment export (`export_for_deployment`) has `deploy: True` and keeps only the networks
that act and infer the context (DEPLOY_MODULES), no optimizers: ~10x smaller, not resumable.
Every tensor must be finite: saving refuses NaN/Inf weights and loading refuses such a file, so a
run poisoned by bad data never reaches evaluation, export or a robot. A file whose sha256 is
recorded (zoo index, card, sidecar, --expect-sha256) must match it (zeus_ros/integrity.py), so
a flipped bit in a finite weight is refused too.
"""

from __future__ import annotations

from dataclasses import dataclass
import io
from pathlib import Path
import pickle
import re
from typing import Any

import torch

from zeus_ros.atomic_file import atomic_write
from zeus_ros.integrity import IntegrityError, check_file, pins_for
from zeus_ros.learning.agent import ZeusAgent
from zeus_ros.learning.config import ZeusConfig, config_from_dict, upgrade_stored_config
from zeus_ros.learning.errors import CheckpointError, CheckpointIntegrityError, ConfigError
from zeus_ros.learning.spec import AgentSpec

__all__ = ['DEPLOY_MODULES', 'FORMAT_VERSION', 'LoadedCheckpoint', 'export_for_deployment',
           'load_checkpoint', 'nonfinite_tensors', 'save_checkpoint', 'save_deployment',
           'stored_task', 'verify_checkpoint']

FORMAT_VERSION = 1
"""Bump when the layout changes; older files are then refused with a clear message."""

DEPLOY_MODULES = ('encoder', 'psi', 'context_norm', 'actor')
"""What acting needs: phi, psi (when the method has one) and the actor."""

_PLAIN = (str, int, float, bool, type(None))


@dataclass(slots=True)
class LoadedCheckpoint:
    """A rebuilt agent and what was stored with it."""

    agent: ZeusAgent
    """The agent with weights (and optimizer states) restored."""
    config: ZeusConfig
    """The resolved ZeusConfig it was trained with."""
    spec: AgentSpec
    """Task side: shapes, bounds, names, normalisation."""
    step: int
    """Update count when saved."""
    extra: dict[str, Any]
    """Caller's plain data (e.g. metrics, replay position)."""
    deploy: bool = False
    """True for a deployment export: acting networks only, cannot resume training."""


def _check_plain(value: Any, where: str) -> None:
    """Refuse anything weights_only loading could not read back (objects, arrays)."""
    if isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f'{where}: keys must be strings, got {key!r}')
            _check_plain(item, f'{where}.{key}')
    elif isinstance(value, list | tuple):
        for index, item in enumerate(value):
            _check_plain(item, f'{where}[{index}]')
    elif not isinstance(value, _PLAIN) and not torch.is_tensor(value):
        raise TypeError(f'{where}: only plain data (str, numbers, bool, None, lists, dicts, '
                        f'tensors) can be stored, got {type(value).__name__}')


def nonfinite_tensors(value: Any, where: str = '') -> tuple[list[str], int]:
    """(names of floating tensors holding NaN/Inf, count of all tensors) in nested data."""
    if torch.is_tensor(value):
        bad = value.is_floating_point() and not bool(torch.isfinite(value).all())
        return ([where or 'tensor'] if bad else []), 1
    items: list[tuple[str, Any]] = []
    if isinstance(value, dict):
        items = [(f'{where}.{key}' if where else str(key), item) for key, item in value.items()]
    elif isinstance(value, list | tuple):
        items = [(f'{where}[{index}]', item) for index, item in enumerate(value)]
    names: list[str] = []
    total = 0
    for name, item in items:
        found, count = nonfinite_tensors(item, name)
        names += found
        total += count
    return names, total


def _nonfinite_message(state: Any) -> str | None:
    """One clause naming the non-finite tensors of a state, or None when all are finite."""
    names, total = nonfinite_tensors(state)
    if not names:
        return None
    return (f'{len(names)} of {total} tensors hold NaN/Inf (first: {", ".join(names[:3])}); '
            'trained on non-finite data or diverged')


def save_checkpoint(path: str | Path, agent: ZeusAgent, *, step: int,
                    extra: dict[str, Any] | None = None) -> Path:
    """Write the agent atomically (temp file + rename) so a crash never leaves half a file.

    Raises:
        CheckpointError: a weight, optimizer state or temperature is NaN/Inf (nothing written).
    """
    payload = _payload(agent, step=step, extra={} if extra is None else extra)
    bad = _nonfinite_message(payload['state'])
    if bad is not None:
        raise _fail(Path(path), f'not saved: {bad}')
    return _write(payload, Path(path))


def _payload(agent: ZeusAgent, *, step: int, extra: dict[str, Any]) -> dict[str, Any]:
    """Everything but the weights is plain data; `state` holds the full agent state."""
    _check_plain(extra, 'extra')
    return {
        'format_version': FORMAT_VERSION,
        'method': agent.method,
        'obs_kind': agent.spec.obs_kind,
        'task': agent.spec.task,
        'k': agent.config.k,
        'aggregation': agent.config.aggregation,
        'context_dim': agent.context_dim,
        'spec': agent.spec.to_dict(),
        'config': agent.config.to_dict(),
        'step': int(step),
        'extra': extra,
        'state': agent.state_dict(),
    }


def _write(payload: dict[str, Any], path: Path) -> Path:
    """torch.save to a temp file + rename, so a crash never leaves half a file.

    Saved through a file handle, so the archive's inner folder is torch's fixed 'archive' and
    not the temp file's name (which holds the pid): the same payload gives the same bytes, and
    re-exporting a checkpoint leaves its sha256 (named on its card) unchanged.
    """
    buffer = io.BytesIO()  # its size first: a full disk then names what the whole file needs
    torch.save(payload, buffer)
    with atomic_write(path, 'wb', size=buffer.getbuffer().nbytes) as handle:
        handle.write(buffer.getbuffer())
    return path


def _fail(path: Path, message: str) -> CheckpointError:
    return CheckpointError(f'checkpoint {path}: {message}')


_TORCH_ADVICE = re.compile(r'weights_only|trusted source|file an issue|documentation of torch'
                           r'|arbitrary code', re.IGNORECASE)


def _load_error(error: Exception) -> str:
    """What was wrong with an unloadable file, without torch's advice to load it unsafely.

    torch suggests retrying with weights_only=False: that runs any code the file holds, so
    that advice (and every line naming weights_only) is dropped; what remains says what it is.
    """
    kept = []
    for line in str(error).splitlines():
        line = line.split('WeightsUnpickler error:')[-1].strip()
        if line and not _TORCH_ADVICE.search(line):
            kept.append(line)
    detail = '; '.join(kept) or 'no detail'
    if isinstance(error, pickle.UnpicklingError) and 'GLOBAL' in detail:
        return (f'refused: it holds more than tensors and plain data ({detail}); zeus_ros '
                'never runs code from a checkpoint')
    return f'unreadable or corrupt ({type(error).__name__}: {detail})'


def verify_checkpoint(path: Path, data: bytes | None, *, sha256: str | None = None,
                      expect_sha256: str | None = None) -> bytes | None:
    """Refuse the file unless it matches every sha256 recorded for it.

    The check itself is zeus_ros/integrity.py's. Returns the bytes to decode: `data`, or the
    file read once here when it has a recorded
    sha256 (hashed, then decoded from memory: what is checked is what is loaded); None (read
    it as usual, unhashed) when nothing is recorded. `sha256`: the digest of `data`, if known.

    Raises:
        CheckpointIntegrityError: a mismatch (one line: the file, both hashes, what to do).
        CheckpointError: an unreadable file or sidecar, or an `expect_sha256` that is no hash.
    """
    try:
        pins = pins_for(path, expect_sha256)
    except IntegrityError as error:
        raise CheckpointIntegrityError(str(error)) from None
    except ValueError as error:  # an expect_sha256 that is no sha256
        raise _fail(path, str(error)) from None
    if not pins:
        return data
    if data is None:
        try:
            data = path.read_bytes()
        except OSError as error:
            raise _fail(path, f'unreadable ({error.strerror or error})') from None
        sha256 = None
    try:
        check_file(path, data, pins, sha256)
    except IntegrityError as error:
        raise CheckpointIntegrityError(str(error)) from None
    return data


def stored_task(path: str | Path) -> str:
    """The task a checkpoint was trained for, read without building its agent.

    For a check that must come before anything starts (`zeus launch` pairing a checkpoint with
    another family's bridge): one safe torch.load, no networks built, no sha256 check (the
    caller's verify_file or load_checkpoint does that). Raises CheckpointError.
    """
    path = Path(path)
    try:
        payload = torch.load(path, map_location='cpu', weights_only=True)
    except FileNotFoundError:
        raise _fail(path, 'no such file') from None
    except Exception as error:  # torch raises many types for corrupt / foreign files
        raise _fail(path, _load_error(error)) from None
    if not isinstance(payload, dict) or 'task' not in payload:
        raise _fail(path, 'not a zeus_ros checkpoint (no task)')
    return str(payload['task'])


def load_checkpoint(path: str | Path, *, map_location: str | torch.device = 'cpu',
                    expect_task: str | None = None, expect_obs_kind: str | None = None,
                    load_optimizers: bool = True, data: bytes | None = None,
                    sha256: str | None = None, expect_sha256: str | None = None,
                    verify: bool = True) -> LoadedCheckpoint:
    """Rebuild the agent stored at `path` on `map_location`, validating it on the way.

    `data`: the file's bytes, already read (a node hashes them to say what it runs): decoded
    instead of reading `path` again, so what is hashed is what is loaded; `path` then names
    the file in errors and says where its card, sidecar or zoo index entry are. `sha256`: the
    digest of `data` when the caller has it (not hashed again).

    A file with a recorded sha256 (`expect_sha256`, a sidecar, its card, the zoo index:
    zeus_ros/integrity.py) is read once, hashed and refused on a mismatch; one without loads
    unhashed.
    `verify=False` only for a file the caller has just written (its card is rewritten next).

    `load_optimizers=False` (and every deployment export) gives an agent that acts only (no
    optimizers: less memory and start-up; `update` refuses).

    Raises:
        CheckpointError: missing or unreadable file, other format version, task or obs-kind
            other than expected, or weights that do not fit the stored shapes.
        CheckpointIntegrityError (a CheckpointError): its sha256 is not the recorded one.
    """
    path = Path(path)
    if data is None and not path.is_file():
        raise _fail(path, 'no such file')
    if verify:
        data = verify_checkpoint(path, data, sha256=sha256, expect_sha256=expect_sha256)
    try:
        device = torch.device(map_location)
    except (RuntimeError, ValueError) as error:
        raise _fail(path, f'cannot load on device {map_location!r} ({error})') from None
    if device.type == 'cuda' and not torch.cuda.is_available():
        raise _fail(path, f'cannot load on device {map_location!r}: '
                    + ('this torch build has no CUDA support' if torch.version.cuda is None
                       else 'no CUDA device is visible') + '; use device cpu')
    try:
        payload = torch.load(path if data is None else io.BytesIO(data),
                             map_location=map_location, weights_only=True)
    except Exception as error:  # torch raises many types for corrupt / foreign files
        raise _fail(path, _load_error(error)) from None
    if not isinstance(payload, dict) or 'format_version' not in payload:
        raise _fail(path, 'not a zeus_ros checkpoint (no format_version)')
    version = payload['format_version']
    if version != FORMAT_VERSION:
        raise _fail(path, f'expected format_version {FORMAT_VERSION}, found {version}')
    missing = [key for key in ('method', 'obs_kind', 'task', 'spec', 'config', 'step', 'state')
               if key not in payload]
    if missing:
        raise _fail(path, f'missing field(s) {", ".join(missing)}')
    mismatches = []
    if expect_task is not None and payload['task'] != expect_task:
        mismatches.append(f"task: expected '{expect_task}', found '{payload['task']}'")
    if expect_obs_kind is not None and payload['obs_kind'] != expect_obs_kind:
        mismatches.append(f"obs_kind: expected '{expect_obs_kind}', "
                          f"found '{payload['obs_kind']}'")
    if mismatches:
        raise _fail(path, '; '.join(mismatches))
    bad = _nonfinite_message(payload['state'])
    if bad is not None:
        raise _fail(path, f'refused: {bad}')
    try:
        spec = AgentSpec.from_dict(payload['spec'])
        config = config_from_dict(upgrade_stored_config(payload['config']), source=str(path))
    except (ConfigError, TypeError, ValueError) as error:
        raise _fail(path, f'invalid stored spec/config ({error})') from None
    if isinstance(config.alpha_psi, str) or isinstance(config.adam_beta1, str):
        raise _fail(path, 'stored config is not resolved (alpha_psi / adam_beta1)')
    deploy = bool(payload.get('deploy', False))
    agent = ZeusAgent(config, spec, device=map_location,
                      optimizers=load_optimizers and not deploy)
    try:
        agent.load_state_dict(payload['state'], optimizers=load_optimizers and not deploy,
                              only=[m for m in DEPLOY_MODULES if m in agent.modules]
                              if deploy else None)
    except (KeyError, RuntimeError, ValueError) as error:
        raise _fail(path, f'weights do not fit the stored shapes ({error})') from None
    return LoadedCheckpoint(agent=agent, config=config, spec=spec, step=int(payload['step']),
                            extra=payload.get('extra', {}), deploy=deploy)


def export_for_deployment(source: str | Path, target: str | Path) -> Path:
    """Write the acting part of `source` to `target` (atomic); returns `target`.

    Raises:
        CheckpointError: `source` is not a valid checkpoint.
    """
    source, target = Path(source), Path(target)
    loaded = load_checkpoint(source, load_optimizers=False)
    return save_deployment(target, loaded.agent, step=loaded.step, extra=loaded.extra)


def save_deployment(path: str | Path, agent: ZeusAgent, *, step: int,
                    extra: dict[str, Any]) -> Path:
    """Write the acting networks of `agent` (DEPLOY_MODULES) as a deployment export (atomic)."""
    keep = [name for name in DEPLOY_MODULES if name in agent.modules]
    payload = _payload(agent, step=step, extra=extra)
    payload['deploy'] = True
    payload['state'] = {'modules': {name: agent.modules[name].state_dict() for name in keep},
                        'optimizers': {}, 'log_alpha': agent.log_alpha.detach().cpu()}
    bad = _nonfinite_message(payload['state'])
    if bad is not None:
        raise _fail(Path(path), f'not saved: {bad}')
    return _write(payload, Path(path))
