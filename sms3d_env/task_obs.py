"""Observation entries in the *estimated* target's frame, the episode's phase and the wrist F/T:
what the training env (``task_obs=True``) adds to the state observation.

Everything here is available on a real robot: the tool pose from the joint encoders, the pose
estimate the perception stage delivers, a clock, the vacuum sensor's "sealed" signal and a wrist
force/torque sensor. Nothing reads the true pose or internal physics loads.
"""

from __future__ import annotations

import math

import numpy as np

#: Entries and sizes, in the order they follow the base observation's entries.
TASK_OBS_SIZES = {
    "tool_in_target": 7,  # tool offset (3, m) and tool axis (3) in the target frame; angle (rad)
    "progress": 3,  # time since reset (s), time since the last seal formed (s, 0 if none), twist (rad)
    "wrist_wrench": 6,  # force (N) and torque (N m) of the tool on the wrist, wrist sensor frame
}


def target_frame(axis: np.ndarray) -> np.ndarray:
    """Rotation (3 x 3, columns x, y, z in world) of the estimated target frame: z the estimated
    stem axis (unit), x the world x axis made orthogonal to it (the cap's yaw is not observable,
    so the frame fixes it by the world; tilts stay below 90 degrees, where this is defined)."""
    z = np.asarray(axis, float) / np.linalg.norm(axis)
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    n = np.linalg.norm(x)
    if n < 1e-6:  # axis along world x: fall back on world y
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
        n = np.linalg.norm(x)
    x /= n
    return np.column_stack([x, np.cross(z, x), z])


def tool_in_target(tool_pos: np.ndarray, tool_axis: np.ndarray, cap_top: np.ndarray,
                   axis: np.ndarray) -> np.ndarray:
    """(7,): the tool site's offset from the estimated cap top and the tool's approach axis, both
    in the estimated target frame, and the angle (rad) between the tool axis and the estimated
    stem axis reversed (0 when the cup faces straight down the stem)."""
    r = target_frame(axis)
    offset = r.T @ (np.asarray(tool_pos, float) - np.asarray(cap_top, float))
    z_local = r.T @ np.asarray(tool_axis, float)
    angle = math.acos(float(np.clip(-z_local[2], -1.0, 1.0)))
    return np.concatenate([offset, z_local, [angle]])


def twist_about(axis: np.ndarray, x_then: np.ndarray, x_now: np.ndarray) -> float:
    """Signed angle (rad, right hand about ``axis``) from ``x_then`` to ``x_now``, both projected
    onto the plane orthogonal to ``axis``: how far the tool has turned about the estimated stem."""
    z = np.asarray(axis, float) / np.linalg.norm(axis)
    a = x_then - (x_then @ z) * z
    b = x_now - (x_now @ z) * z
    return math.atan2(float(np.cross(a, b) @ z), float(a @ b))
