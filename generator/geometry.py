"""Small geometry helpers over arrays: rotations and oriented boxes."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np


def rotation_xyz(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (the paper's composition), angles in radians."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` radians about ``axis`` (any non-zero length)."""
    axis = np.asarray(axis, dtype=float)
    q = np.zeros(4)
    mujoco.mju_axisAngle2Quat(q, axis / np.linalg.norm(axis), angle)
    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, q)
    return r.reshape(3, 3)


def tilt_angle(rotation: np.ndarray) -> float:
    """Angle in radians between a frame's +z axis and world +z."""
    return float(np.arccos(np.clip(rotation[2, 2], -1.0, 1.0)))


_CORNER_SIGNS = np.array(
    [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float
)


@dataclass(frozen=True)
class OrientedBox:
    """A box with centre, full edge lengths ``size`` and orientation ``rotation`` (world frame)."""

    center: np.ndarray
    size: np.ndarray
    rotation: np.ndarray

    @property
    def corners(self) -> np.ndarray:
        """The 8 corners, shape (8, 3), in a fixed order (x slowest, z fastest)."""
        local = _CORNER_SIGNS * (np.asarray(self.size) / 2.0)
        return local @ np.asarray(self.rotation).T + np.asarray(self.center)

    def to_dict(self) -> dict[str, list]:
        return {
            "center": np.asarray(self.center).tolist(),
            "size": np.asarray(self.size).tolist(),
            "rotation": np.asarray(self.rotation).tolist(),
            "corners": self.corners.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict) -> OrientedBox:
        return cls(
            center=np.asarray(data["center"], dtype=float),
            size=np.asarray(data["size"], dtype=float),
            rotation=np.asarray(data["rotation"], dtype=float),
        )
