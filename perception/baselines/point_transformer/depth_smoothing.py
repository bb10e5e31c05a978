"""Smoothing a mushroom's depth inside its mask before its points are taken.

A stereo camera's depth noise is correlated over its matching window (the camera model's
``correlated_noise``: 7 × 7 pixels, σ_z ≈ 1.9 mm at 0.4 m for a D405), so neighbouring points of
a cloud move together and no local feature averages the noise away. A cap is a smooth dome a
few dozen pixels across: a Gaussian-weighted mean over the mask's own valid pixels (a
normalised convolution, so no soil or neighbour depth leaks in) leaves its shape and removes
most of the noise. Intel ships the same idea as the RealSense SDK's spatial post-processing
filter (an edge-preserving smoothing of the depth image; Intel, "Depth Post-Processing for
Intel RealSense D400 Depth Cameras", white paper, 2018).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

#: A pixel that the mean would move by more than this (m) keeps its own depth: a rim against a
#: deeper neighbour or a flying pixel, which a mean would drag towards the wrong surface.
DEFAULT_MAX_SHIFT_M = 0.006


def smooth_depth_in_mask(depth: np.ndarray, mask: np.ndarray, sigma_px: float,
                         max_shift_m: float = DEFAULT_MAX_SHIFT_M) -> np.ndarray:
    """A copy of ``depth (H, W)`` (metres; 0, NaN or inf invalid) whose valid pixels inside
    ``mask (H, W) bool`` hold the value at that pixel of a plane fitted to the valid mask pixels
    around it, weighted by a Gaussian of standard deviation ``sigma_px`` pixels, unless that
    value lies more than ``max_shift_m`` from the pixel's own depth.

    A plane rather than a mean: near a rim the mask's pixels lie on one side only, and a mean of
    a dome's pixels there would lift the rim towards the apex (0.9 mm of a 4 mm fall at 4 px);
    a local plane follows the slope (first-order normalised convolution, Knutsson & Westin,
    CVPR 1993). Where the pixels around cannot fix a plane (a sliver one or two pixels wide) the
    weighted mean is used. Pixels outside the mask and invalid pixels are returned unchanged;
    ``sigma_px`` 0 returns an unchanged copy. Only the mask's bounding box (plus 3σ) is
    filtered, so the cost follows the mask's size, not the image's.
    """
    if sigma_px < 0 or not math.isfinite(sigma_px):
        raise ValueError(f"sigma_px must be a finite number >= 0, got {sigma_px!r}")
    out = np.array(depth, dtype=np.float32, copy=True)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != out.shape:
        raise ValueError(f"mask shape {mask.shape} differs from depth shape {out.shape}")
    valid = mask & np.isfinite(out) & (out > 0)
    if sigma_px == 0 or not valid.any():
        return out
    rows, cols = np.nonzero(valid)
    margin = math.ceil(3 * sigma_px)
    r0, r1 = max(rows.min() - margin, 0), min(rows.max() + margin + 1, out.shape[0])
    c0, c1 = max(cols.min() - margin, 0), min(cols.max() + margin + 1, out.shape[1])
    box, inside = out[r0:r1, c0:c1], valid[r0:r1, c0:c1]
    own = box[inside].astype(np.float64)
    weight = inside.astype(np.float64)
    z = np.where(inside, box - own.mean(), 0.0)  # about the mean depth: no precision lost
    y, x = np.mgrid[: box.shape[0], : box.shape[1]].astype(np.float64)
    x, y = x - x.mean(), y - y.mean()
    ksize = 2 * margin + 1

    def blur(image: np.ndarray) -> np.ndarray:
        smooth = cv2.GaussianBlur(image, (ksize, ksize), sigma_px, borderType=cv2.BORDER_CONSTANT)
        return smooth[inside]

    # Gaussian-weighted moments of the valid pixels about each pixel (u, v: their offsets).
    s0, sx, sy, sz = blur(weight), blur(weight * x), blur(weight * y), blur(weight * z)
    sxx, sxy, syy = blur(weight * x * x), blur(weight * x * y), blur(weight * y * y)
    sxz, syz = blur(weight * x * z), blur(weight * y * z)
    px, py = x[inside], y[inside]
    su, sv = sx - px * s0, sy - py * s0
    suu = sxx - 2 * px * sx + px * px * s0
    svv = syy - 2 * py * sy + py * py * s0
    suv = sxy - px * sy - py * sx + px * py * s0
    suz, svz = sxz - px * sz, syz - py * sz
    # The plane z = a + b u + c v through the weighted points, solved for a (Cramer's rule).
    det = s0 * (suu * svv - suv * suv) - su * (su * svv - suv * sv) + sv * (su * suv - suu * sv)
    det_a = sz * (suu * svv - suv * suv) - su * (suz * svv - suv * svz) + sv * (suz * suv - suu * svz)
    # A full disc of support gives det / s0^3 = sigma^4; far less means too thin to fix a plane.
    planar = det > 0.05 * sigma_px**4 * s0**3
    fitted = np.where(planar, det_a / np.where(planar, det, 1.0), sz / s0) + own.mean()
    box[inside] = np.where(np.abs(fitted - own) <= max_shift_m, fitted, own).astype(np.float32)
    return out
