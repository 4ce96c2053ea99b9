"""Errors raised by the learning core, so callers can catch them by kind."""

from __future__ import annotations

__all__ = ['CheckpointError', 'ConfigError']


class ConfigError(ValueError):
    """A training configuration is malformed: unknown key, bad type or out-of-range value."""


class CheckpointError(RuntimeError):
    """A checkpoint is missing, unreadable, of another format version or for another setup."""
