"""Typed errors raised by the generator for bad input."""

from __future__ import annotations


class ConfigError(ValueError):
    """An invalid configuration value; ``field`` names the offending field, ``message`` says
    what is wrong with it (a command line can report it by the flag that set the field)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message

    def __reduce__(self):  # picklable across worker processes
        return (type(self), (self.field, self.message))


class MeshError(ValueError):
    """A mushroom mesh that cannot be used (not watertight, no cap, unreadable)."""


class SceneFormatError(ValueError):
    """A scene file that cannot be read back (corrupt JSON, wrong schema version)."""
