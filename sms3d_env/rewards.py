"""Rewards: dense shaping (approach, axis alignment, seal, detach, lift) and sparse success."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

REWARD_TYPES = ("dense", "sparse")


@dataclass(frozen=True)
class RewardState:
    tool_pos: np.ndarray
    tool_axis: np.ndarray  # cup +z (approach direction)
    est_cap_top: np.ndarray
    est_axis: np.ndarray
    gripped_target: bool
    target_detached: bool
    lift: float  # m the target's cap top rose since reset
    lift_goal: float
    success: bool
    bruised: bool


def compute_reward(s: RewardState, reward_type: str) -> float:
    """Sparse: 0 on success, -1 otherwise (Gymnasium-Robotics convention).

    Dense: -distance to the estimated cap top (m) + 0.1 x alignment of the cup axis with the
    estimated stem axis + 0.5 sealed on the target + 1 detached *and held* + 2 x lift fraction
    while held + 5 success - 2 bruise. The detach and lift terms pay only while the cup holds the
    target: paid for detachment alone, PPO learned to knock targets off their roots and collect
    the bonus every step without ever holding one.
    """
    if reward_type == "sparse":
        return 0.0 if s.success else -1.0
    dist = math.dist(s.tool_pos, s.est_cap_top)
    align = -float(s.tool_axis @ s.est_axis)
    r = -dist + 0.1 * align
    held = s.gripped_target
    r += 0.5 * held + 1.0 * (s.target_detached and held)
    r += 2.0 * min(max(s.lift / s.lift_goal, 0.0), 1.0) * held
    r += 5.0 * s.success - 2.0 * s.bruised
    return r
