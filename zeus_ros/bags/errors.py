"""Errors of the offline data path (schema, bags, ingest, replay)."""

from __future__ import annotations

from pathlib import Path

__all__ = ['BagError', 'IngestError', 'SchemaError']


class SchemaError(Exception):
    """The zeus_msgs definitions cannot be found or do not match what a bag holds."""


class BagError(Exception):
    """A bag cannot be read: missing, corrupt, truncated or written with another schema."""

    def __init__(self, path: Path | str, reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(f'{self.path}: {reason}')

    def __reduce__(self) -> tuple[type, tuple[Path, str]]:
        """Picklable as raised (a collect worker's error reaches its parent whole)."""
        return type(self), (self.path, self.reason)


class IngestError(Exception):
    """Bags were readable but their content is inconsistent (raised in strict mode)."""
