"""The output folder of a long-running command (``sms3d train-*``): one rule for all of them.

A folder records the settings it was made with (``run_settings.json``). Opening it again with
the same settings resumes the run; other settings are refused with the differing fields named,
unless the caller asks to ``overwrite`` (start anew, explicitly). A folder holding files that no
run wrote is never reused silently. The settings file is written only once the caller has
checked every input, so a refused command leaves the folder as it was.

One process at a time runs in a folder: :func:`open_run_folder` takes an exclusive
``fcntl.flock`` on the folder's ``run.lock`` and the returned :class:`RunFolder` holds it until it
is released (``with open_run_folder(...) as run:``) or the process ends, however it ends: the
operating system drops the lock of a killed process, so no stale lock is ever left to clear by
hand. A second run in the folder meanwhile is refused, naming the folder and the holder's pid.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import shutil
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from generator.files import write_atomic

#: The settings record in every run folder.
SETTINGS_FILE = "run_settings.json"
#: The lock file of every run folder (it holds the running process's id, for the refusal).
LOCK_FILE = "run.lock"
#: The errors that say a folder cannot be written to (its mode, a read-only file system).
_READ_ONLY = (errno.EACCES, errno.EPERM, errno.EROFS)


class RunFolderError(ValueError):
    """An output folder cannot be used as asked (names the folder and what differs)."""

    def __init__(self, folder: str | Path, message: str) -> None:
        self.folder = str(folder)
        super().__init__(f"{folder}: {message}")


@dataclass(frozen=True)
class RunFolder:
    """An opened run folder: ``resumed`` when it already held a run with the same settings;
    ``writable`` False for a resumed folder this process may not write (a finished run is still
    read from it: :meth:`check_writable` before writing). Holds the folder's lock until
    :meth:`release` (or the end of a ``with`` block, or of the process)."""

    path: Path
    resumed: bool
    writable: bool = True
    _lock: IO[str] | None = field(default=None, repr=False, compare=False)

    def check_writable(self) -> None:
        """``RunFolderError`` unless the run may write its folder."""
        if not self.writable:
            raise RunFolderError(self.path, "holds an unfinished run but is not writable (its permissions or a "
                                            "read-only file system); make it writable to resume, or use another "
                                            "--out")

    def release(self) -> None:
        """Let another process run in the folder (closing the lock file drops its lock)."""
        if self._lock is not None:
            self._lock.close()

    def __enter__(self) -> RunFolder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _normalised(settings: Mapping[str, Any]) -> dict[str, Any]:
    """``settings`` as JSON gives it back (tuples become lists, keys strings), so that a record
    read from disk compares equal to the settings that wrote it."""
    try:
        return json.loads(json.dumps(dict(settings)))
    except (TypeError, ValueError) as exc:
        raise TypeError(f"run settings must be JSON values ({exc})") from exc


def check_out_path(out: str | Path, flag: str = "--out") -> Path:
    """``out`` as a folder path; ``RunFolderError`` naming ``flag`` when it is empty or a file."""
    if not str(out).strip():
        raise RunFolderError(repr(str(out)), f"{flag} must name a folder, got an empty path")
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise RunFolderError(path, f"{flag} must be a folder; a file of that name exists")
    return path


def differing_settings(recorded: Mapping[str, Any], wanted: Mapping[str, Any],
                       may_change: Iterable[str] = ()) -> list[str]:
    """The keys whose values differ between two settings records, ``may_change`` aside; each as
    ``key (recorded → wanted)``."""
    old, new, free = _normalised(recorded), _normalised(wanted), set(may_change)
    return [f"{k} ({old.get(k)!r} → {new.get(k)!r})" for k in sorted(set(old) | set(new))
            if k not in free and old.get(k) != new.get(k)]


def _run_files(path: Path) -> list[Path]:
    """What ``path`` holds besides its lock file (a folder that holds only the lock file of a run
    killed before it recorded its settings is empty)."""
    return [p for p in path.iterdir() if p.name != LOCK_FILE] if path.is_dir() else []


def _empty(path: Path) -> None:
    """Remove what ``path`` holds but its lock file, which the caller holds: removing it would let
    another process lock a new one beside this run. The folder itself stays, so that ``path``
    may be a symbolic link to it."""
    for entry in _run_files(path):
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()


def lock_run_folder(path: Path) -> IO[str] | None:
    """The open lock file of the folder ``path`` (made if missing), locked by this process; None
    when the folder may not be written (nothing to protect: no run can write it).
    ``RunFolderError`` naming the folder and the holder's pid when another process holds it."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        lock = open(path / LOCK_FILE, "a+", encoding="utf-8")  # noqa: SIM115  (held beyond this call)
    except OSError as exc:
        if exc.errno in _READ_ONLY and path.is_dir():
            return None
        raise RunFolderError(path, f"cannot be made or written ({exc.strerror})") from None
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        lock.seek(0)
        holder = lock.read().strip() or "unknown"
        lock.close()
        raise RunFolderError(path, f"another run is in progress in this folder (process {holder} holds "
                                   f"{LOCK_FILE}); wait for it to end, or use another --out") from None
    lock.seek(0)
    lock.truncate()
    lock.write(str(os.getpid()))
    lock.flush()
    return lock


def open_run_folder(out: str | Path, settings: Mapping[str, Any], *, overwrite: bool = False,
                    may_change: Iterable[str] = (), may_grow: Iterable[str] = (),
                    flag: str = "--out") -> RunFolder:
    """Open ``out`` for a run with ``settings``: a new folder, or a resumed one.

    - missing or empty: created, ``settings`` recorded; ``resumed=False``;
    - made with the same settings (``may_change`` aside, e.g. a worker count, and ``may_grow``
      where the new value is at least the recorded one, e.g. episodes that extend a run):
      ``resumed=True``, the record updated to the new values;
    - made with other settings: ``RunFolderError`` naming the differing fields, unless
      ``overwrite``, which empties the folder first;
    - holding files without a settings record: ``RunFolderError`` (``overwrite`` never empties a
      folder that no run made);
    - locked by another process's run: ``RunFolderError`` (:func:`lock_run_folder`).

    A resumed folder whose record is unchanged is not written, so that a finished run is read
    from a folder this process may not write (``writable=False``).
    """
    path = check_out_path(out, flag)
    wanted = _normalised(settings)
    record = path / SETTINGS_FILE
    existing = bool(_run_files(path))
    if existing and not record.is_file():
        # Never emptied, even with ``overwrite``: ``--out . --overwrite`` must not delete a
        # working folder.
        raise RunFolderError(path, f"holds files but no {SETTINGS_FILE}, so it is no run of this command; "
                                   f"use another {flag} (or empty it yourself)")
    lock = lock_run_folder(path)
    try:
        if existing and overwrite:
            if lock is None:
                raise RunFolderError(path, "is not writable, so --overwrite cannot empty it")
            _empty(path)
        elif existing:
            recorded = _recorded_settings(record)
            grow = tuple(may_grow)
            differing = differing_settings(recorded, wanted, (*may_change, *grow))
            differing += [f"{k} ({recorded[k]!r} → {wanted[k]!r}: it may only grow)" for k in grow
                          if k in recorded and k in wanted and wanted[k] < recorded[k]]
            if differing:
                raise RunFolderError(path, f"holds a run made with other settings: {', '.join(differing)}; "
                                           f"rerun with the same settings to resume, use another {flag}, "
                                           "or --overwrite to start anew")
            if lock is not None and recorded != wanted:
                write_atomic(record, json.dumps(wanted, indent=2))
            return RunFolder(path, resumed=True, writable=lock is not None, _lock=lock)
        if lock is None:
            raise RunFolderError(path, "is not writable (its permissions or a read-only file system)")
        write_atomic(record, json.dumps(wanted, indent=2))
        return RunFolder(path, resumed=False, _lock=lock)
    except BaseException:
        if lock is not None:
            lock.close()
        raise


def _recorded_settings(record: Path) -> dict[str, Any]:
    """The settings a run folder's ``record`` holds; ``RunFolderError`` naming it if unreadable."""
    try:
        recorded = json.loads(record.read_text(encoding="utf-8"))
        if not isinstance(recorded, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as exc:
        raise RunFolderError(record, f"unreadable settings record ({exc}); use --overwrite to start anew") from exc
    return recorded
