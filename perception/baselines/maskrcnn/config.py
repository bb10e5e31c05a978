"""Mask R-CNN's network (``DetectorConfig``, stored in checkpoints) and training settings
(``DetectorTrainConfig``), without torch: ``sms3d train-detector --help`` reads its defaults here."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from perception.choices import ARCHITECTURES, CATEGORIES
from perception.errors import PerceptionConfigError


@dataclass(frozen=True)
class DetectorConfig:
    """What defines a detector network; stored in its checkpoints.

    ``category`` is the dataset's COCO category it detects (``mushroom``: the visible whole
    mushroom, which the pose network's default input needs; ``mushroom_cap``: the visible cap).
    Images are used at their own size when it lies within ``min_size``/``max_size`` (640 × 480
    is not rescaled by default: upscaling would only cost time on a CPU).
    """

    arch: str = "mobilenet_v3_fpn"
    category: str = "mushroom"
    min_size: int = 480
    max_size: int = 640
    score_threshold: float = 0.5
    mask_threshold: float = 0.5

    def __post_init__(self) -> None:
        if self.arch not in ARCHITECTURES:
            raise PerceptionConfigError("arch", f"{self.arch!r} is not one of {ARCHITECTURES}")
        if self.category not in CATEGORIES:
            raise PerceptionConfigError("category", f"{self.category!r} is not one of {tuple(CATEGORIES)}")
        if not 32 <= self.min_size <= self.max_size:
            raise PerceptionConfigError("min_size", f"need 32 <= min_size <= max_size, got {self.min_size}, {self.max_size}")
        for name in ("score_threshold", "mask_threshold"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise PerceptionConfigError(name, f"must lie in [0, 1), got {getattr(self, name)}")

    @property
    def category_id(self) -> int:
        return CATEGORIES[self.category]

    def architecture(self) -> dict[str, Any]:
        """The fields that shape the weights (thresholds do not)."""
        return {"arch": self.arch, "category": self.category}


@dataclass(frozen=True)
class DetectorTrainConfig:
    """Optimisation settings. AdamW with a linear warm-up and a cosine decay to zero over all
    epochs suits training from scratch on small synthetic sets (at a constant rate the scores of
    a from-scratch network keep swinging from epoch to epoch); ``max_images`` caps the training images (for smoke runs and overfitting);
    ``passes_per_epoch`` repeats a small training set within an epoch, so that tiny sets are not
    checkpointed and validated after every iteration."""

    epochs: int = 20
    batch_size: int = 2
    lr: float = 3e-4
    weight_decay: float = 1e-4
    warmup_iters: int = 100
    seed: int = 0
    augment: bool = True
    max_images: int | None = None
    passes_per_epoch: int = 1
    pretrained: bool = False
    val_split: str = "val"
    max_val_images: int | None = 20

    def __post_init__(self) -> None:
        for name in ("epochs", "batch_size", "passes_per_epoch"):
            if getattr(self, name) < 1:
                raise PerceptionConfigError(name, f"must be >= 1, got {getattr(self, name)}")
        if not (self.lr > 0 and math.isfinite(self.lr)):
            raise PerceptionConfigError("lr", f"must be a positive number, got {self.lr}")
        if self.max_images is not None and self.max_images < 1:
            raise PerceptionConfigError("max_images", f"must be >= 1, got {self.max_images}")
