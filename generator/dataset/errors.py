"""Typed errors of dataset writing and reading; each names the offending file or folder."""

from __future__ import annotations

from pathlib import Path


class DatasetError(RuntimeError):
    """Base class of dataset errors."""


class DatasetWriteError(DatasetError):
    """Output cannot be written (folder not writable, disk full, a scene that failed)."""

    def __init__(self, path: str | Path, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = Path(path)
        self.message = message

    def __reduce__(self):  # picklable across worker processes
        return (type(self), (str(self.path), self.message))


class CorruptFileError(DatasetError):
    """A dataset file that is missing, unreadable, truncated or fails its checksum."""

    def __init__(self, path: str | Path, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = Path(path)
        self.message = message

    def __reduce__(self):
        return (type(self), (str(self.path), self.message))


class ManifestMismatchError(DatasetError):
    """Resuming into a folder whose manifest, or one of whose scenes (by its ``scene.json``), was
    made with other settings; the message names the folder or file and each differing setting."""
