"""The RGB-D segmenter's settings, without torch (``sms3d --help`` reads their defaults).

``SegmenterConfig`` defines the network and how its heads become instances (stored in each
checkpoint); ``SegmenterTrainConfig`` how it is trained (``perception.detection.train_segmenter``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from perception.errors import PerceptionConfigError


@dataclass(frozen=True)
class SegmenterConfig:
    """What defines the network (``widths``) and how its heads become instances (the rest);
    stored in checkpoints. Defaults are those of the shipped model."""

    widths: tuple[int, ...] = (16, 32, 64, 96, 128)
    centre_sigma_px: float = 2.5  # half-resolution pixels, the Gaussian of the centre target
    mask_threshold: float = 0.5
    centre_threshold: float = 0.3
    peak_window: int = 7  # half-resolution pixels
    min_area: int = 16  # full-resolution pixels: smaller instances are dropped
    score_threshold: float = 0.5  # what F1 counts (COCO AP uses every detection)

    def __post_init__(self) -> None:
        widths = tuple(int(w) for w in self.widths)
        object.__setattr__(self, "widths", widths)
        if len(widths) != 5 or any(w < 4 for w in widths):
            raise PerceptionConfigError("widths", f"need five widths >= 4, got {self.widths!r}")
        for name in ("mask_threshold", "centre_threshold", "score_threshold"):
            if not 0.0 < getattr(self, name) < 1.0:
                raise PerceptionConfigError(name, f"must lie in (0, 1), got {getattr(self, name)!r}")
        if not self.centre_sigma_px > 0:
            raise PerceptionConfigError("centre_sigma_px", f"must be > 0, got {self.centre_sigma_px!r}")
        if self.peak_window < 1 or self.peak_window % 2 == 0:
            raise PerceptionConfigError("peak_window", f"must be an odd integer >= 1, got {self.peak_window!r}")
        if self.min_area < 1:
            raise PerceptionConfigError("min_area", f"must be >= 1, got {self.min_area!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class SegmenterTrainConfig:
    """Optimisation settings (AdamW, linear warm-up, cosine decay to zero over ``epochs``; an
    epoch is one random crop of every training scene)."""

    epochs: int = 60
    batch_size: int = 16
    crop: int = 160  # half-resolution pixels
    lr: float = 2e-3
    weight_decay: float = 1e-4
    warmup_iters: int = 50
    seed: int = 0
    time_limit_min: float | None = None
    val_every: int = 5
    max_val_images: int = 10  # per dataset folder

    def __post_init__(self) -> None:
        for name in ("epochs", "batch_size", "crop", "val_every", "max_val_images"):
            if getattr(self, name) < 1:
                raise PerceptionConfigError(name, f"must be >= 1, got {getattr(self, name)}")
        if not (self.lr > 0 and math.isfinite(self.lr)):
            raise PerceptionConfigError("lr", f"must be a positive number, got {self.lr}")
        if self.time_limit_min is not None and not self.time_limit_min > 0:
            raise PerceptionConfigError("time_limit_min", f"must be > 0, got {self.time_limit_min}")
