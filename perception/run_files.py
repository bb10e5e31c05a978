"""What a training run writes and reads and how its rate moves, shared by the pose, axis-CNN,
segmenter and Mask R-CNN trainers: checkpoints and ``log.csv`` replaced atomically (a run killed
at any point leaves the previous file whole), checkpoints read without running code from them,
the line a resumed run prints, and the warm-up + cosine learning-rate schedule."""

from __future__ import annotations

import csv
import hashlib
import math
import os
import sys
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch

from generator.files import write_via_temp
from perception.errors import CheckpointFormatError


def atomic_torch_save(obj: Any, path: str | Path) -> None:
    """``torch.save`` to a temporary file in the same folder, then ``os.replace`` it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_via_temp(path, lambda tmp: torch.save(obj, tmp))


def read_torch_file(path: str | Path, what: str) -> Any:
    """The contents of a ``torch.save`` file, read with ``weights_only=True``: tensors and plain
    values (dicts, lists, strings, numbers) only, so that loading a file never runs code from it.

    Raises:
        FileNotFoundError: no such file (named, with ``what`` it should be).
        CheckpointFormatError: not a readable ``what``, e.g. a file that pickles other objects.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such {what}")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many unrelated types for a file that is not a checkpoint
        reason = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else 'unreadable'}"
        if "weights only" in reason.lower():  # torch's refusal, worded as advice to load it unsafely
            reason = "it pickles Python objects besides tensors and plain values, which could run code, so it is not loaded"
        raise CheckpointFormatError(f"{path}: not a readable {what} ({reason})") from exc


def checksum(*arrays: np.ndarray) -> str:
    """A short SHA-256 of the arrays' shapes, types and bytes: what a run records of the data it
    was given, so that a rerun on other data is told apart from a resume."""
    digest = hashlib.sha256()
    for array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype.str}{array.shape}".encode())
        digest.update(array.data)
    return digest.hexdigest()[:16]


def say_resumed(out: str | Path, epochs_done: int, epochs: int) -> None:
    """Tell a user who reran a command that it continues the run in ``out``, not a new one."""
    if epochs_done >= epochs:
        print(f"{out} is complete ({epochs_done} of {epochs} epochs); nothing left to train", file=sys.stderr)
    else:
        print(f"resuming {out} from epoch {epochs_done} of {epochs}", file=sys.stderr)


def write_log_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    """The per-epoch ``rows`` as CSV, atomically; columns in the order they first appear (rows
    that were not validated leave the validation columns empty)."""
    fields = list(dict.fromkeys(k for row in rows for k in row))
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, path)


class WarmupCosine(Protocol):
    lr: float
    warmup_iters: int


def learning_rate(train: WarmupCosine, iteration: int, total: int) -> float:
    """Linear warm-up over ``train.warmup_iters``, then cosine decay from ``train.lr`` to zero at
    ``total`` iterations."""
    warmup = min(1.0, (iteration + 1) / max(train.warmup_iters, 1))
    return train.lr * warmup * 0.5 * (1.0 + math.cos(math.pi * min(iteration / max(total, 1), 1.0)))
