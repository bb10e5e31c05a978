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
    - ``occlusion_prob`` / ``occlusion_fraction``: with this probability a training cloud, before
      it is sampled and normalised, loses a share drawn from ``occlusion_fraction`` of its points
      to an occluder beside it in the image (:func:`occlude_points`). With oracle masks on the
      clean held-out beds, caps under 95 % visible make 61 % of the summed stem-axis error; the
      same mushrooms rendered alone read 2.7° instead of 6.9°.
    """

    scale_range: tuple[float, float] = (0.85, 1.15)
    jitter_std: float = 0.01
    jitter_clip: float = 0.03
    noise_std: float = 0.01
    permute: bool = True
    occlusion_prob: float = 0.0
    occlusion_fraction: tuple[float, float] = (0.2, 0.6)

    def __post_init__(self) -> None:
        lo, hi = self.scale_range
        if not 0 < lo <= hi:
            raise PerceptionConfigError("scale_range", f"need 0 < min <= max, got {self.scale_range!r}")
        for name in ("jitter_std", "jitter_clip", "noise_std"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise PerceptionConfigError(name, f"must be a finite number >= 0, got {v!r}")
        if not (np.isfinite(self.occlusion_prob) and 0 <= self.occlusion_prob <= 1):
            raise PerceptionConfigError("occlusion_prob", f"must be in [0, 1], got {self.occlusion_prob!r}")
        lo, hi = self.occlusion_fraction
        if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi < 1):
            raise PerceptionConfigError("occlusion_fraction", f"need 0 < min <= max < 1, got {self.occlusion_fraction!r}")


def occlude_points(
    points: np.ndarray, fraction: float, rng: np.random.Generator, colors: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """``points (N, 3)`` in the camera frame (z forward, metres) without the ``fraction`` of them
    that a neighbour in front would hide: the points whose image-plane projection ``(x/z, y/z)``
    lies nearest to a centre placed in a random direction from the cloud's centroid, 0.6-1.2
    times the cloud's image radius out, so that the hidden part is a disc-shaped bite from one
    side, as a neighbouring cap takes. Non-finite points are dropped first; ``colors`` are cut
    alike. A cloud that would keep fewer than ``MIN_POINTS`` points is returned unchanged."""
    from perception.pointcloud import MIN_POINTS  # imports torch, which the CLI's help does without

    finite = np.isfinite(points).all(1) & (points[:, 2] > 0)
    pts = points[finite]
    cols = None if colors is None else colors[finite]
    keep_n = len(pts) - int(round(fraction * len(pts)))
    if keep_n < MIN_POINTS:
        return points, colors
    uv = pts[:, :2] / pts[:, 2:3]
    centre = uv.mean(0)
    radius = float(np.linalg.norm(uv - centre, axis=1).max())
    angle = rng.uniform(0.0, 2.0 * np.pi)
    occluder = centre + radius * rng.uniform(0.6, 1.2) * np.array([np.cos(angle), np.sin(angle)])
    keep = np.argsort(-np.linalg.norm(uv - occluder, axis=1))[:keep_n]
    keep.sort()
    return pts[keep], None if cols is None else cols[keep]


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
