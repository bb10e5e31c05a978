"""What a pose source returns and what it is: ``PoseEstimate`` and the ``PoseSource`` protocol.

A pose source is any callable ``(scene, instance_id, rng) -> PoseEstimate``, called once per
episode at reset (a scan before the pick); its estimate is the target pose in the observation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np


@dataclass(frozen=True)
class PoseEstimate:
    """Estimated target pose: cap-top centre (m, world) and rotation (stem axis = column 2)."""

    cap_top: np.ndarray
    rotation: np.ndarray

    @property
    def stem_axis(self) -> np.ndarray:
        return self.rotation[:, 2].copy()


class PoseSource(Protocol):
    def __call__(self, scene: Any, instance_id: int, rng: np.random.Generator) -> PoseEstimate: ...
