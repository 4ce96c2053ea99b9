"""Errors raised by the learning core, so callers can catch them by kind."""

from __future__ import annotations

__all__ = ['CheckpointError', 'CheckpointIntegrityError', 'ConfigError']


class ConfigError(ValueError):
    """A training configuration is malformed: unknown key, bad type or out-of-range value."""


class CheckpointError(RuntimeError):
    """A checkpoint is missing, unreadable, of another format version or for another setup."""


class CheckpointIntegrityError(CheckpointError):
    """A checkpoint's bytes are not its recorded sha256: corrupt or tampered (zeus_ros/integrity).

    Also raised when its record (a sidecar) is unusable: a pin must never fail open.
    """
