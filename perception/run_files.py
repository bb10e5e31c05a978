"""What a training run writes and how its rate moves, shared by the pose, segmenter and Mask
R-CNN trainers: checkpoints and ``log.csv`` replaced atomically (a run killed at any point leaves
the previous file whole), and the warm-up + cosine learning-rate schedule."""

from __future__ import annotations

import csv
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Protocol

import torch


def atomic_torch_save(obj: Any, path: str | Path) -> None:
    """``torch.save`` to a temporary file in the same folder, then ``os.replace`` it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    os.close(fd)
    try:
        torch.save(obj, tmp)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; checkpoints are ordinary files
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


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
