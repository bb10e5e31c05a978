"""Depth images to per-mushroom point clouds: back-projection, filtering, sampling, normalising.

Camera frame and intrinsics follow OpenCV: x right, y down, z forward (metres); pixel ``(u, v)``
= (column, row); ``x = (u - cx) z / fx``, ``y = (v - cy) z / fy``. Depth is metric ``z`` (not
range); ``0``, negative, NaN and inf depths are invalid and never produce points.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np
import torch

from generator.dataset.backproject import backproject
from perception.errors import DegenerateCloud, NoEstimate, PerceptionConfigError, PipelineInputError

#: Fewest valid points from which a pose is estimated; fewer gives :class:`NoEstimate`.
MIN_POINTS: int = 16
#: Least spread (standard deviation, m) of a cloud across its main direction; below it the points
#: are all at one place or on one line (:class:`DegenerateCloud`). Views of a mushroom spread
#: 5 mm or more (smallest 4.9 mm over 200 synthetic views and 5 generated beds' masks); a
#: one-pixel-wide line of pixels spreads about 0.01 mm.
MIN_SPREAD_M: float = 1e-4
# Planar depth of a bed seen from 7 cm to 2 m: a median outside this range is the wrong unit.
PLAUSIBLE_DEPTH_M = (0.05, 3.0)

SamplingMethod = Literal["random", "fps"]
SAMPLING_METHODS: tuple[str, ...] = get_args(SamplingMethod)


@dataclass(frozen=True)
class Pinhole:
    """Checked pinhole parameters in pixels (OpenCV convention): what back-projection needs.

    Not a second camera description: ``generator.camera.Intrinsics`` is the camera (with its
    image size); this is what ``pinhole_intrinsics`` makes of it, or of a bare 3x3 matrix ``K``,
    after checking that every value is finite and the focal lengths positive."""

    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise PerceptionConfigError(name, f"must be a finite number, got {v!r}")
        for name in ("fx", "fy"):
            if getattr(self, name) <= 0:
                raise PerceptionConfigError(name, f"must be > 0, got {getattr(self, name)!r}")

    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix ``K``."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)


def pinhole_intrinsics(intrinsics: Any) -> Pinhole:
    """Checked :class:`Pinhole` from anything with ``fx, fy, cx, cy`` (``generator.camera.Intrinsics``,
    a ``Pinhole``) or from a 3x3 camera matrix ``K``.

    Raises :class:`PerceptionConfigError` naming the field: ``intrinsics`` for neither, ``fx``
    etc. for a value that is not finite or a focal length that is not positive (which would
    otherwise turn every point into NaN, reported as "too few points")."""
    if isinstance(intrinsics, Pinhole):
        return intrinsics
    if isinstance(intrinsics, (np.ndarray, list, tuple)):
        K = np.asarray(intrinsics, dtype=np.float64)
        if K.shape != (3, 3) or K[0, 1] != 0 or K[1, 0] != 0 or not np.array_equal(K[2], [0, 0, 1]):
            raise PerceptionConfigError("intrinsics", "expected a pinhole camera matrix [[fx, 0, cx], [0, fy, cy], "
                                                      f"[0, 0, 1]], got {K.tolist()!r}")
        return Pinhole(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))
    names = ("fx", "fy", "cx", "cy")
    if not all(hasattr(intrinsics, n) for n in names):
        raise PerceptionConfigError("intrinsics", f"expected fx, fy, cx, cy or a 3x3 camera matrix, got "
                                                  f"{type(intrinsics).__name__}")
    values = [getattr(intrinsics, n) for n in names]
    # numpy scalars count as numbers; anything else goes on to Pinhole, which names it.
    return Pinhole(*(float(v) if isinstance(v, numbers.Real) and not isinstance(v, bool) else v for v in values))


def check_metres(depth: np.ndarray, name: str) -> None:
    """Raise :class:`PipelineInputError` naming ``name`` if the median of the valid (finite,
    positive) ``depth`` values is no plausible camera distance in metres (millimetres, say)."""
    depth = np.asarray(depth)
    valid = depth[np.isfinite(depth) & (depth > 0)]
    if valid.size:
        median = float(np.median(valid))
        if not PLAUSIBLE_DEPTH_M[0] <= median <= PLAUSIBLE_DEPTH_M[1]:
            raise PipelineInputError(f"{name}: median {median:.3g} is not a plausible distance in metres "
                                     f"(expected {PLAUSIBLE_DEPTH_M[0]}-{PLAUSIBLE_DEPTH_M[1]} m); wrong unit?")


def check_sampling(method: str, name: str) -> None:
    """Raise :class:`PerceptionConfigError` naming ``name`` unless ``method`` is a sampling method."""
    if method not in SAMPLING_METHODS:
        raise PerceptionConfigError(name, f"must be one of {SAMPLING_METHODS}, got {method!r}")


def check_cloud(points: np.ndarray, min_points: int = MIN_POINTS) -> None:
    """Raise :class:`NoEstimate` for fewer than ``min_points`` ``points (N, 3)`` (finite), and
    :class:`DegenerateCloud` for points all at one place or on one line."""
    if len(points) < min_points:
        raise NoEstimate(len(points), min_points)
    # The second-largest principal standard deviation: zero for a point or a line.
    spread = float(np.sqrt(max(np.linalg.eigvalsh(np.cov(np.asarray(points, np.float64).T, bias=True))[1], 0.0)))
    if spread < MIN_SPREAD_M:
        raise DegenerateCloud(len(points), min_points, spread, MIN_SPREAD_M)


def depth_to_points(
    depth: np.ndarray,
    intrinsics: Any,
    mask: np.ndarray | None = None,
    rgb: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Back-project the valid, masked pixels of ``depth`` to camera-frame points.

    Args:
        depth: ``(H, W)`` metric depth (m); ``<= 0``, NaN and inf are invalid.
        intrinsics: pinhole intrinsics of the depth image (anything with fx, fy, cx, cy, e.g.
            ``generator.camera.Intrinsics``, a ``Pinhole``, or a 3x3 camera
            matrix ``K``; see :func:`pinhole_intrinsics`).
        mask: optional ``(H, W)`` boolean instance mask; all pixels when ``None``.
        rgb: optional ``(H, W, 3)`` image (uint8 or float in [0, 1]).

    Returns:
        ``(points (N, 3) float32, colors (N, 3) float32 in [0, 1] or None)``; ``N`` may be 0.
    """
    depth = np.asarray(depth)
    intrinsics = pinhole_intrinsics(intrinsics)
    # The project's one back-projection (generator's, so datasets and perception agree).
    points, pixels = backproject(depth, intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy,
                                 None if mask is None else np.asarray(mask))
    points = points.astype(np.float32)
    v, u = pixels[:, 0], pixels[:, 1]
    colors = None
    if rgb is not None:
        rgb = np.asarray(rgb)
        if rgb.shape[:2] != depth.shape or rgb.ndim != 3 or rgb.shape[2] < 3:
            raise ValueError(f"rgb: expected shape {depth.shape + (3,)}, got {rgb.shape}")
        c = rgb[v, u, :3].astype(np.float32)
        colors = c / 255.0 if np.issubdtype(rgb.dtype, np.integer) else c
    return points, colors


def filter_finite(points: np.ndarray, colors: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Drop points with any NaN/inf coordinate (and their colours)."""
    points = np.asarray(points, dtype=np.float32)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points: expected shape (N, 3), got {points.shape}")
    keep = np.isfinite(points).all(axis=1)
    if colors is not None:
        colors = np.asarray(colors, dtype=np.float32)
        if colors.shape != points.shape:
            raise ValueError(f"colors: shape {colors.shape} differs from points shape {points.shape}")
        keep &= np.isfinite(colors).all(axis=1)
        colors = colors[keep]
    return points[keep], colors


def farthest_point_indices(points: np.ndarray, n: int, start: int | None = None) -> np.ndarray:
    """Indices of ``n`` farthest-point samples of ``points`` (``n <= len(points)``).

    Starts from ``start`` or, by default, from the point farthest from the centroid, which makes
    the selected *set* independent of the input order.
    """
    pts = np.asarray(points, dtype=np.float64)
    m = len(pts)
    if not 0 < n <= m:
        raise ValueError(f"n: need 0 < n <= {m}, got {n}")
    if start is None:
        start = int(np.argmax(((pts - pts.mean(0)) ** 2).sum(1)))
    idx = np.empty(n, dtype=np.int64)
    dist = np.full(m, np.inf)
    far = start
    for i in range(n):
        idx[i] = far
        d = ((pts - pts[far]) ** 2).sum(1)
        np.minimum(dist, d, out=dist)
        far = int(np.argmax(dist))
    return idx


def sample_points(
    points: np.ndarray,
    n: int,
    rng: np.random.Generator,
    method: SamplingMethod = "random",
    colors: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Sample exactly ``n`` points: without replacement when there are enough, else all points
    plus random repeats. ``method="fps"`` uses farthest-point sampling (slower, even coverage)."""
    check_sampling(method, "method")
    m = len(points)
    if m == 0:
        raise NoEstimate(0, MIN_POINTS, "empty point cloud")
    if m >= n:
        idx = rng.choice(m, size=n, replace=False) if method == "random" else farthest_point_indices(points, n)
    else:
        idx = np.concatenate((rng.permutation(m), rng.integers(0, m, size=n - m)))
    return points[idx], None if colors is None else colors[idx]


def normalize_points(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Centre on the centroid and scale into the unit sphere.

    Returns ``(normalised (N, 3) float32, centre (3,), scale)`` with
    ``points = normalised * scale + centre``. Rotation labels are unaffected.
    """
    pts = np.asarray(points, dtype=np.float64)
    centre = pts.mean(axis=0)
    scale = float(np.sqrt(((pts - centre) ** 2).sum(1)).max())
    if not np.isfinite(scale) or scale <= 1e-9:
        scale = 1.0
    return ((pts - centre) / scale).astype(np.float32), centre, scale


@dataclass(frozen=True)
class PreparedCloud:
    """A network-ready cloud: ``points`` normalised, plus what undoes the normalisation."""

    points: np.ndarray  # (n, 3) float32, unit sphere
    colors: np.ndarray | None  # (n, 3) float32 in [0, 1]
    centre: np.ndarray  # (3,) camera frame, metres (centroid of the valid input points)
    scale: float  # metres
    num_valid: int  # valid points before sampling


def prepare_cloud(
    points: np.ndarray,
    n: int,
    rng: np.random.Generator,
    colors: np.ndarray | None = None,
    method: SamplingMethod = "random",
    min_points: int = MIN_POINTS,
) -> PreparedCloud:
    """Filter, check, sample and normalise one cloud; raise :class:`NoEstimate` if fewer than
    ``min_points`` finite points remain, :class:`DegenerateCloud` if they lie on one line."""
    points, colors = filter_finite(points, colors)
    check_cloud(points, min_points)
    centre = points.astype(np.float64).mean(0)
    pts, cols = sample_points(points, n, rng, method, colors)
    normed, _, scale = normalize_points(pts)
    # Centre on the full cloud's centroid, not the sample's, for a stable reported centre.
    normed = ((pts.astype(np.float64) - centre) / scale).astype(np.float32)
    return PreparedCloud(normed, cols, centre, scale, len(points))


def to_tensor(points: np.ndarray, colors: np.ndarray | None = None) -> torch.Tensor:
    """``(N, 3)`` (+ ``(N, 3)`` colours) to a ``(N, 3 or 6)`` float32 tensor."""
    feats = points if colors is None else np.concatenate((points, colors), axis=1)
    return torch.from_numpy(np.ascontiguousarray(feats, dtype=np.float32))
