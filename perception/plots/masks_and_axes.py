"""A picture of what stage 1 and stage 2 saw: each detection's mask tinted over the RGB image,
and each estimate's stem axis drawn from its cap top (camera-frame estimates projected with the
camera matrix ``K``). No ground truth is needed: it draws what a robot would act on."""

from __future__ import annotations

import cv2
import numpy as np

from perception.pipeline import MushroomEstimate

#: Length of the drawn stem axis, metres (about a cap's diameter).
AXIS_LENGTH_M = 0.04


def _colour(k: int) -> tuple[int, int, int]:
    """A bright colour per instance (golden-ratio hues)."""
    hsv = np.uint8([[[int(179 * ((k * 0.618034) % 1.0)), 200, 255]]])
    return tuple(int(c) for c in cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0, 0])


def draw_masks_and_axes(rgb: np.ndarray, estimates: list[MushroomEstimate], K: np.ndarray,
                        alpha: float = 0.45) -> np.ndarray:
    """``(H, W, 3)`` uint8: ``rgb`` with every estimate's mask tinted, its outline and its stem
    axis (cap top -> cap top - ``AXIS_LENGTH_M`` x axis, i.e. down the stem) drawn."""
    out = rgb.astype(np.float32).copy()
    K = np.asarray(K, dtype=float)
    for k, est in enumerate(estimates):
        colour = np.array(_colour(k), np.float32)
        mask = est.detection.mask
        out[mask] = (1 - alpha) * out[mask] + alpha * colour
    out = out.clip(0, 255).astype(np.uint8)
    for k, est in enumerate(estimates):
        colour = _colour(k)
        contours, _ = cv2.findContours(est.detection.mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(out, contours, -1, colour, 1, cv2.LINE_AA)
        top = est.cap_top_cam
        base = top - AXIS_LENGTH_M * est.stem_axis_cam
        pts = []
        for p in (top, base):
            if p[2] <= 0:  # behind the camera: nothing to draw
                break
            uvw = K @ p
            pts.append((int(round(uvw[0] / uvw[2])), int(round(uvw[1] / uvw[2]))))
        if len(pts) == 2:
            cv2.arrowedLine(out, pts[1], pts[0], (255, 255, 255), 2, cv2.LINE_AA, tipLength=0.25)
            cv2.arrowedLine(out, pts[1], pts[0], colour, 1, cv2.LINE_AA, tipLength=0.25)
    return out
