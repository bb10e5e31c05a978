"""Rotation error metrics in degrees: full geodesic error and stem-axis error."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from perception.pose.rotations import axis_angle_error, geodesic_angle


@dataclass(frozen=True)
class PoseMetrics:
    """Summary of per-sample errors (degrees)."""

    mean_geodesic_deg: float
    median_geodesic_deg: float
    mean_axis_deg: float
    median_axis_deg: float
    count: int

    def as_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def errors_deg(pred: torch.Tensor, target: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample ``(geodesic, axis)`` errors in degrees for ``(B, 3, 3)`` rotations."""
    with torch.no_grad():
        g = torch.rad2deg(geodesic_angle(pred.double(), target.double(), eps=0.0))
        a = torch.rad2deg(axis_angle_error(pred.double(), target.double(), eps=0.0))
    return g.cpu().numpy(), a.cpu().numpy()


def summarize(geodesic_deg: np.ndarray, axis_deg: np.ndarray) -> PoseMetrics:
    """Means and medians of per-sample errors."""
    g, a = np.asarray(geodesic_deg, float), np.asarray(axis_deg, float)
    if len(g) == 0:
        raise ValueError("no errors to summarise")
    return PoseMetrics(float(g.mean()), float(np.median(g)), float(a.mean()), float(np.median(a)), len(g))
