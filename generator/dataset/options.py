"""Dataset options: splits, rendering and seeded realism (all realism off by default)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from generator.config import is_number
from generator.errors import ConfigError

# RealSense-like stereo baselines in metres (docs/physics.md, cameras).
STEREO_BASELINE_M = {"d405": 0.018, "d435": 0.050}


@dataclass(frozen=True)
class RealismOptions:
    """Seeded sensor and appearance randomisation. Every switch is off by default."""

    depth_noise: bool = False  # sigma_z = z^2 * subpixel / (f_px * baseline)
    depth_noise_subpixel: float = 0.08  # px, Intel's typical value (0.032 at best)
    edge_holes: bool = False  # invalid (0) depth at depth discontinuities, like stereo sensors
    edge_threshold: float = 0.008  # m, neighbour depth step that counts as an edge
    edge_hole_probability: float = 0.6  # chance an edge pixel (dilated by 1 px) becomes a hole
    lighting: bool = False  # light intensity, direction and ambient jitter
    soil: bool = False  # soil tint and texture repeat jitter
    camera_jitter: bool = False  # camera height and tilt jitter
    camera_height_jitter: float = 0.03  # m, uniform +-
    camera_tilt_jitter_deg: float = 5.0  # deg, tilt away from straight down about a random axis

    def __post_init__(self) -> None:
        for name in ("depth_noise_subpixel", "edge_threshold", "camera_height_jitter", "camera_tilt_jitter_deg"):
            v = getattr(self, name)
            if not is_number(v) or not math.isfinite(v) or v < 0:
                raise ConfigError(f"realism.{name}", f"must be a finite number >= 0, got {v!r}")
        p = self.edge_hole_probability
        if not is_number(p) or not 0 <= p <= 1:
            raise ConfigError("realism.edge_hole_probability", f"must be in [0, 1], got {p!r}")
        if self.camera_tilt_jitter_deg > 30:
            raise ConfigError("realism.camera_tilt_jitter_deg", "must be <= 30")

    @property
    def any(self) -> bool:
        return self.depth_noise or self.edge_holes or self.lighting or self.soil or self.camera_jitter


@dataclass(frozen=True)
class DatasetOptions:
    """How scenes become dataset files (the scene itself comes from ``SceneConfig``)."""

    split_ratios: tuple[float, float, float] = (0.8, 0.1, 0.1)  # train, val, test
    shadows: bool = False
    realism: RealismOptions = field(default_factory=RealismOptions)

    def __post_init__(self) -> None:
        ratios = tuple(float(r) for r in self.split_ratios)
        object.__setattr__(self, "split_ratios", ratios)
        if len(ratios) != 3 or any(not math.isfinite(r) or r < 0 for r in ratios) or sum(ratios) <= 0:
            raise ConfigError("split_ratios", f"need three finite ratios >= 0 with a positive sum, got {self.split_ratios!r}")
        if isinstance(self.realism, Mapping):
            object.__setattr__(self, "realism", RealismOptions(**self.realism))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> DatasetOptions:
        try:
            return cls(split_ratios=tuple(data.get("split_ratios", (0.8, 0.1, 0.1))),
                       shadows=bool(data.get("shadows", False)),
                       realism=RealismOptions(**dict(data.get("realism", {}))))
        except TypeError as exc:
            raise ConfigError("dataset", str(exc)) from exc
