"""The ``"oracle"`` and ``"noisy"`` pose sources: the truth, and the truth with an exact error.

``OraclePose`` returns the scene's pose; ``NoisyPose`` rotates it by exactly ``pose_error_deg``
about a random axis perpendicular to the stem (and optionally adds Gaussian position noise or an
exact cap-top offset); ``UniformNoisyPose`` draws that error per episode.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from generator.geometry import axis_angle_matrix
from sms3d_env.pose_sources.base import PoseEstimate


class OraclePose:
    """The ground-truth pose from the scene."""

    def __call__(self, scene: Any, instance_id: int, rng: np.random.Generator) -> PoseEstimate:
        inst = scene.instances[instance_id]
        return PoseEstimate(np.asarray(inst.cap_top, float).copy(), np.asarray(inst.rotation, float).copy())


class NoisyPose:
    """Truth rotated by exactly ``error_deg`` about a random axis perpendicular to the stem.

    The cap-top centre is kept (it is what a camera sees best) unless ``position_std`` > 0 (m),
    which adds isotropic Gaussian noise, or ``position_error`` > 0 (m), which moves it by exactly
    that distance: in a random direction perpendicular to the *estimated* stem axis, or along it
    (outwards, above the cap) with ``along_axis=True``. The direction is drawn after the
    rotation, so every position error shares the rotation of the same seed (a paired design).
    """

    def __init__(self, error_deg: float, position_std: float = 0.0, position_error: float = 0.0,
                 along_axis: bool = False) -> None:
        if not np.isfinite(error_deg) or not 0 <= error_deg <= 180:
            raise ValueError(f"pose_error_deg must be in [0, 180], got {error_deg!r}")
        if not np.isfinite(position_std) or position_std < 0:
            raise ValueError(f"position_std must be >= 0, got {position_std!r}")
        if not np.isfinite(position_error) or position_error < 0:
            raise ValueError(f"position_error must be a finite distance >= 0 (m), got {position_error!r}")
        if position_std > 0 and position_error > 0:
            raise ValueError("position_std and position_error exclude each other")
        self.error = np.deg2rad(error_deg)
        self.position_std, self.position_error, self.along_axis = position_std, position_error, along_axis

    def __call__(self, scene: Any, instance_id: int, rng: np.random.Generator) -> PoseEstimate:
        truth = OraclePose()(scene, instance_id, rng)
        phi = rng.uniform(0, 2 * np.pi)
        e1 = truth.rotation[:, 0]
        e2 = truth.rotation[:, 1]
        perp = np.cos(phi) * e1 + np.sin(phi) * e2
        rot = axis_angle_matrix(perp, self.error) @ truth.rotation if self.error > 0 else truth.rotation
        centre = truth.cap_top + (rng.normal(0, self.position_std, 3) if self.position_std > 0 else 0)
        if self.position_error > 0:
            if self.along_axis:
                offset = rot[:, 2]
            else:
                psi = rng.uniform(0, 2 * np.pi)
                offset = np.cos(psi) * rot[:, 0] + np.sin(psi) * rot[:, 1]
            centre = centre + self.position_error * offset
        return PoseEstimate(np.asarray(centre, float), rot)


class UniformNoisyPose:
    """A ``NoisyPose`` whose error is drawn per episode, uniformly in ``[low_deg, high_deg]``:
    training under a spread of pose errors (the error is not observed, as on a robot)."""

    def __init__(self, low_deg: float, high_deg: float) -> None:
        if not (np.isfinite(low_deg) and np.isfinite(high_deg) and 0 <= low_deg <= high_deg <= 180):
            raise ValueError(f"need 0 <= low_deg <= high_deg <= 180, got {low_deg!r}, {high_deg!r}")
        self.low_deg, self.high_deg = float(low_deg), float(high_deg)

    def __call__(self, scene: Any, instance_id: int, rng: np.random.Generator) -> PoseEstimate:
        return NoisyPose(rng.uniform(self.low_deg, self.high_deg))(scene, instance_id, rng)
