"""The output folder of a long-running command (``sms3d train-*``): one rule for all of them.

A folder records the settings it was made with (``run_settings.json``). Opening it again with
the same settings resumes the run; other settings are refused with the differing fields named,
unless the caller asks to ``overwrite`` (start anew, explicitly). A folder holding files that no
run wrote is never reused silently. The settings file is written only once the caller has
checked every input, so a refused command leaves the folder as it was.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from generator.files import write_atomic

#: The settings record in every run folder.
SETTINGS_FILE = "run_settings.json"


class RunFolderError(ValueError):
    """An output folder cannot be used as asked (names the folder and what differs)."""

    def __init__(self, folder: str | Path, message: str) -> None:
        self.folder = str(folder)
        super().__init__(f"{folder}: {message}")


@dataclass(frozen=True)
class RunFolder:
    """An opened run folder: ``resumed`` when it already held a run with the same settings."""

    path: Path
    resumed: bool


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
      folder that no run made).
    """
    path = check_out_path(out, flag)
    wanted = _normalised(settings)
    record = path / SETTINGS_FILE
    if path.is_dir() and any(path.iterdir()):
        if not record.is_file():
            # Never emptied, even with ``overwrite``: ``--out . --overwrite`` must not delete a
            # working folder.
            raise RunFolderError(path, f"holds files but no {SETTINGS_FILE}, so it is no run of this command; "
                                       f"use another {flag} (or empty it yourself)")
        if overwrite:
            shutil.rmtree(path)
        else:
            try:
                recorded = json.loads(record.read_text(encoding="utf-8"))
                if not isinstance(recorded, dict):
                    raise ValueError("not a JSON object")
            except (OSError, ValueError) as exc:
                raise RunFolderError(record, f"unreadable settings record ({exc}); use --overwrite to start "
                                             "anew") from exc
            grow = tuple(may_grow)
            differing = differing_settings(recorded, wanted, (*may_change, *grow))
            differing += [f"{k} ({recorded[k]!r} → {wanted[k]!r}: it may only grow)" for k in grow
                          if k in recorded and k in wanted and wanted[k] < recorded[k]]
            if differing:
                raise RunFolderError(path, f"holds a run made with other settings: {', '.join(differing)}; "
                                           f"rerun with the same settings to resume, use another {flag}, "
                                           "or --overwrite to start anew")
            write_atomic(record, json.dumps(wanted, indent=2))
            return RunFolder(path, resumed=True)
    path.mkdir(parents=True, exist_ok=True)
    write_atomic(record, json.dumps(wanted, indent=2))
    return RunFolder(path, resumed=False)
