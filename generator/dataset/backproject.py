"""Depth image to camera-frame points (OpenCV: x right, y down, z forward; metres).

``x = (u - cx) z / fx``, ``y = (v - cy) z / fy`` with pixel ``(u, v)`` = (column, row) and pixel
centres at integer coordinates. Depth is planar ``z``; ``<= 0``, NaN and inf are invalid.
The project's one back-projection: ``perception`` should call this rather than keep its own.
"""

from __future__ import annotations

import numpy as np


def backproject_pixels(u: np.ndarray, v: np.ndarray, z: np.ndarray, fx: float, fy: float, cx: float,
                       cy: float) -> np.ndarray:
    """Points (N, 3) float64 of pixels ``(u, v)`` at depths ``z``."""
    z = np.asarray(z, dtype=np.float64)
    return np.stack(((np.asarray(u) - cx) * z / fx, (np.asarray(v) - cy) * z / fy, z), axis=-1)


def backproject(depth: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame points (N, 3) float64 of the valid (and masked) pixels, and their (N, 2)
    ``(v, u)`` pixel indices."""
    depth = np.asarray(depth)
    if depth.ndim != 2:
        raise ValueError(f"depth: expected shape (H, W), got {depth.shape}")
    valid = np.isfinite(depth) & (depth > 0)
    if mask is not None:
        if mask.shape != depth.shape:
            raise ValueError(f"mask: shape {mask.shape} differs from depth shape {depth.shape}")
        valid &= mask.astype(bool)
    v, u = np.nonzero(valid)
    return backproject_pixels(u, v, depth[v, u], fx, fy, cx, cy), np.stack((v, u), axis=1)
