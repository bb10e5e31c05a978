"""Stage 1 detectors behind one interface: instance masks with boxes and scores.

``detections_from_labels`` is the oracle: it reads MuJoCo's segmentation render (instance labels,
id + 1, 0 = background), so the pose network can be measured alone. A learned detector (Mask
R-CNN) implements the same ``Detector`` protocol.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Detection:
    """One detected mushroom: a boolean mask, its box ``(x0, y0, x1, y1)`` in pixels (inclusive
    corners), a score, and the ground-truth instance id when the detector knows it (oracle)."""

    mask: np.ndarray
    box: tuple[int, int, int, int]
    score: float
    instance_id: int | None = None

    @property
    def area(self) -> int:
        return int(self.mask.sum())


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks (0 when both are empty)."""
    return float((a & b).sum() / max((a | b).sum(), 1))


def matched_detections(detections: list[Detection], labels: np.ndarray,
                       min_iou: float = 0.5) -> list[tuple[Detection, int, float]]:
    """``(detection, instance id, IoU)`` for each detection matched to a ground-truth mushroom of
    the instance label image ``labels`` (id + 1 per pixel): best score first, each to the
    not-yet-taken mushroom its mask overlaps best, with visible-mask IoU >= ``min_iou``."""
    out = []
    taken: set[int] = set()
    for det in sorted(detections, key=lambda d: -d.score):
        candidates = np.unique(labels[det.mask])
        best, best_iou = None, min_iou
        for value in candidates[candidates > 0]:
            iid = int(value) - 1
            if iid in taken:
                continue
            iou = mask_iou(det.mask, labels == value)
            if iou >= best_iou:
                best, best_iou = iid, iou
        if best is not None:
            taken.add(best)
            out.append((det, best, best_iou))
    return out


class Detector(Protocol):
    """What stage 1 is: one RGB-D image (``rgb (H, W, 3)`` uint8, ``depth (H, W)`` float metres,
    0 = invalid) to instance detections. RGB-only detectors ignore ``depth``."""

    def detect(self, rgb: np.ndarray, depth: np.ndarray | None = None) -> list[Detection]: ...


def detections_from_labels(labels: np.ndarray, min_pixels: int = 1) -> list[Detection]:
    """Oracle detections from an instance label image (uint, id + 1 per instance, 0 background),
    ordered by instance id; instances with fewer than ``min_pixels`` visible pixels are left out."""
    labels = np.asarray(labels)
    if labels.ndim != 2 or not np.issubdtype(labels.dtype, np.integer):
        raise ValueError(f"labels: expected an (H, W) integer image, got {labels.shape} {labels.dtype}")
    detections = []
    for value in np.unique(labels):
        if value == 0:
            continue
        mask = labels == value
        if mask.sum() < min_pixels:
            continue
        rows, cols = np.nonzero(mask)
        box = (int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max()))
        detections.append(Detection(mask, box, 1.0, int(value) - 1))
    return detections
