"""Atomic file writes: a reader never sees a half-written file, a crash leaves the old one."""

from __future__ import annotations

import json
import os
import re
import shutil
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

#: A temporary's name: ``<stem>.tmp<pid><suffix>`` (:func:`temp_path`).
_TEMP_NAME = re.compile(r".*\.tmp(?P<pid>\d+)(\.[^.]*)?")


def temp_path(path: str | Path) -> Path:
    """Where this process writes ``path`` before renaming it into place: beside it, with the same
    suffix and this process's id in the name (``model.tmp1234.zip``), so that two processes never
    share one and :func:`remove_orphaned_temporaries` knows whose it is."""
    path = Path(path)
    return path.with_name(f"{path.stem}.tmp{os.getpid()}{path.suffix}")


def process_alive(pid: int) -> bool:
    """Whether a process of id ``pid`` runs now (a process of another user counts)."""
    try:
        os.kill(pid, 0)  # signal 0: nothing is sent, only whether the process exists is checked
    except PermissionError:
        return True
    except (OSError, OverflowError):  # ProcessLookupError, or an id no process can have
        return False
    return True


def remove_orphaned_temporaries(folder: str | Path) -> list[Path]:
    """Remove the temporaries (:func:`temp_path`, files or folders) in ``folder`` whose process
    has died: what a killed run (``kill -9``, a power cut) left, which no ``finally`` removed. A
    live process's are kept. Returns what was removed."""
    folder = Path(folder)
    removed = []
    for entry in folder.iterdir() if folder.is_dir() else ():
        match = _TEMP_NAME.fullmatch(entry.name)
        if match is None or process_alive(int(match["pid"])):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        removed.append(entry)
    return removed


def write_via_temp(path: str | Path, write: Callable[[Path], Any]) -> None:
    """``write(temp)`` to a temporary file beside ``path`` (the same suffix, so that writers that
    add one, numpy's and stable-baselines3's, add none; the process id in its name, so that two
    processes never share one), then rename it into place. A write killed at any moment leaves
    the old file or none, never part of one; a failed one leaves no temporary file behind."""
    path = Path(path)
    tmp = temp_path(path)
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_atomic(path: str | Path, data: str | bytes) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` through :func:`write_via_temp`."""
    if isinstance(data, str):
        write_via_temp(path, lambda tmp: tmp.write_text(data, encoding="utf-8"))
    else:
        write_via_temp(path, lambda tmp: tmp.write_bytes(data))


def save_rgb_png(path: str | Path, image: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 RGB image as a PNG, atomically; ``OSError`` if it cannot be encoded."""
    ok, png = cv2.imencode(".png", cv2.cvtColor(np.asarray(image), cv2.COLOR_RGB2BGR))
    if not ok:
        raise OSError(f"cannot encode {path} as PNG")
    write_atomic(path, png.tobytes())


def save_npz_atomic(path: str | Path, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
    """``arrays`` and ``meta`` (JSON) written to ``path`` through a temporary file and a rename, so
    that a killed run leaves the old file or none, never half of one."""
    write_via_temp(path, lambda tmp: np.savez_compressed(tmp, __meta__=np.array(json.dumps(meta)), **arrays))


def read_npz_made_with(path: str | Path, meta: dict[str, Any]) -> dict[str, np.ndarray] | None:
    """``path``'s arrays if it was written (by ``save_npz_atomic``) with ``meta``; None if it is
    missing, unreadable, cut short or made with other settings."""
    try:
        with np.load(path) as z:
            if json.loads(str(z["__meta__"])) == meta:
                return {k: z[k] for k in z.files if k != "__meta__"}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        pass
    return None
