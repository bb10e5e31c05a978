"""Training-time augmentation of normalised clouds that leaves the rotation label unchanged."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from perception.errors import PerceptionConfigError


@dataclass(frozen=True)
class AugmentConfig:
    """Augmentation strengths, in units of the normalised (unit-sphere) cloud.

    - ``scale_range``: isotropic scaling (rotations are scale invariant).
    - ``jitter_std`` / ``jitter_clip``: per-point clipped Gaussian jitter (PointNet style).
    - ``noise_std``: Gaussian noise along the camera's z axis, like depth-sensor noise.
    - ``permute``: shuffle the point order.
    """

    scale_range: tuple[float, float] = (0.85, 1.15)
    jitter_std: float = 0.01
    jitter_clip: float = 0.03
    noise_std: float = 0.01
    permute: bool = True

    def __post_init__(self) -> None:
        lo, hi = self.scale_range
        if not 0 < lo <= hi:
            raise PerceptionConfigError("scale_range", f"need 0 < min <= max, got {self.scale_range!r}")
        for name in ("jitter_std", "jitter_clip", "noise_std"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise PerceptionConfigError(name, f"must be a finite number >= 0, got {v!r}")


def augment_points(
    points: np.ndarray, cfg: AugmentConfig, rng: np.random.Generator, colors: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Scale, jitter and add depth noise to ``points (N, 3)``, then permute points and colours
    together; returns ``(points, colors)``."""
    p = points * rng.uniform(*cfg.scale_range)
    if cfg.jitter_std > 0:
        p = p + np.clip(rng.normal(0, cfg.jitter_std, p.shape), -cfg.jitter_clip, cfg.jitter_clip)
    if cfg.noise_std > 0:
        p[:, 2] += rng.normal(0, cfg.noise_std, len(p))
    if cfg.permute:
        perm = rng.permutation(len(p))
        p = p[perm]
        colors = None if colors is None else colors[perm]
    return p.astype(np.float32), colors
