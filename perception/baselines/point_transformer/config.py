"""The pose network's shape (``PoseNetConfig``) and training settings (``TrainConfig``), without
torch, so that ``sms3d train-pose`` checks its recipe (:mod:`.recipe`) before loading it;
checkpoints store the first."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from perception.baselines.point_transformer.augment import AugmentConfig
from perception.choices import BACKBONE_NAMES, HEAD_NAMES, ROTATION_LOSSES
from perception.errors import PerceptionConfigError

Head = Literal["6d", "6d_stem", "9d", "quat", "euler"]  # perception.choices.HEAD_NAMES


def _cuda_available() -> bool:
    import torch

    return torch.cuda.is_available()


@dataclass(frozen=True)
class PoseNetConfig:
    """Shape of a :class:`PoseNet` and what it is fed; validated on construction.

    ``depth_smoothing_px``: the network reads clouds whose depth was smoothed inside each mask
    with a Gaussian of this many pixels (:func:`perception.baselines.point_transformer.depth_smoothing.smooth_depth_in_mask`)
    before back-projection; ``PosePipeline`` does the same for it. 0 (the default, and every
    checkpoint saved before the field existed): raw depth. It shapes no weight, so fine-tuning
    (``init``) may change it.
    """

    backbone: str = "point_transformer"
    head: Head = "6d"
    use_rgb: bool = False
    num_points: int = 1024
    hidden: int = 128  # width of the head MLP
    depth_smoothing_px: float = 0.0

    #: Fields that describe the network's input rather than its weights.
    INPUT_FIELDS = ("depth_smoothing_px",)

    def __post_init__(self) -> None:
        if self.backbone not in BACKBONE_NAMES:
            raise PerceptionConfigError("backbone", f"expected one of {sorted(BACKBONE_NAMES)}, got {self.backbone!r}")
        if self.head not in HEAD_NAMES:
            raise PerceptionConfigError("head", f"expected one of {sorted(HEAD_NAMES)}, got {self.head!r}")
        if not isinstance(self.use_rgb, bool):
            raise PerceptionConfigError("use_rgb", f"must be a bool, got {self.use_rgb!r}")
        for name, lo in (("num_points", 16), ("hidden", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise PerceptionConfigError(name, f"must be an int >= {lo}, got {v!r}")
        s = self.depth_smoothing_px
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not np.isfinite(s) or not 0 <= s <= 20:
            raise PerceptionConfigError("depth_smoothing_px", f"must be a number in [0, 20] (pixels), got {s!r}")

    @property
    def in_channels(self) -> int:
        return 6 if self.use_rgb else 3

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PoseNetConfig:
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise PerceptionConfigError(unknown[0], "unknown PoseNetConfig field")
        return cls(**d)


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation settings (the network's shape is a :class:`PoseNetConfig`)."""

    epochs: int = 50
    batch_size: int = 32
    lr: float = 1e-4
    weight_decay: float = 0.0
    loss: str = "geodesic"
    plateau_factor: float = 0.5
    plateau_patience: int = 5
    min_lr: float = 1e-6
    seed: int = 0
    device: str = "cpu"
    num_workers: int = 0
    augment: AugmentConfig | None = field(default_factory=AugmentConfig)
    progress: bool = True
    time_limit_s: float | None = None  # stop after the first epoch that ends past this budget
    select_by: str = "loss"  # best.pt: lowest validation "loss", or lowest mean stem-"axis" error

    def __post_init__(self) -> None:
        for name in ("epochs", "batch_size", "plateau_patience"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise PerceptionConfigError(name, f"must be an int >= 1, got {v!r}")
        if not isinstance(self.num_workers, int) or self.num_workers < 0:
            raise PerceptionConfigError("num_workers", f"must be an int >= 0, got {self.num_workers!r}")
        for name in ("lr", "plateau_factor"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise PerceptionConfigError(name, f"must be a finite number > 0, got {v!r}")
        if not 0 < self.plateau_factor < 1:
            raise PerceptionConfigError("plateau_factor", f"must be in (0, 1), got {self.plateau_factor!r}")
        if not (np.isfinite(self.weight_decay) and self.weight_decay >= 0):
            raise PerceptionConfigError("weight_decay", f"must be >= 0, got {self.weight_decay!r}")
        if self.select_by not in ("loss", "axis"):
            raise PerceptionConfigError("select_by", f"expected 'loss' or 'axis', got {self.select_by!r}")
        if self.loss not in ROTATION_LOSSES:
            raise PerceptionConfigError("loss", f"expected one of {ROTATION_LOSSES}, got {self.loss!r}")
        if self.device != "cpu" and not self.device.startswith("cuda"):
            raise PerceptionConfigError("device", f"expected 'cpu' or 'cuda[:i]', got {self.device!r}")
        if self.device.startswith("cuda") and not _cuda_available():
            raise PerceptionConfigError("device", "CUDA requested but not available")

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        return d
