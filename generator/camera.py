"""Overhead RGB-D camera: RealSense-like intrinsics and OpenCV-convention poses."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from generator.config import CameraConfig

# Focal length in pixels at 640 x 480 (docs/physics.md, camera and depth sensor).
FOCAL_PX_640x480 = {"d405": 382.0, "d435": 430.0}
# OpenCV camera frame (x right, y down, z forward) from MuJoCo's (x right, y up, looking along -z).
MUJOCO_TO_OPENCV = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels (OpenCV convention)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    @property
    def fovy_deg(self) -> float:
        return math.degrees(2 * math.atan(self.height / 2 / self.fy))

    def to_dict(self) -> dict[str, float]:
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy}


def camera_intrinsics(config: CameraConfig) -> Intrinsics:
    """Intrinsics of the preset, scaled to the configured height (square pixels).

    The principal point is where MuJoCo renders the optical axis: on the corner shared by the
    four centre pixels, ``(W/2 - 0.5, H/2 - 0.5)`` in OpenCV's convention (pixel centres at
    integers)."""
    f = FOCAL_PX_640x480[config.preset] * config.height / 480.0
    return Intrinsics(config.width, config.height, f, f, config.width / 2.0 - 0.5, config.height / 2.0 - 0.5)


def camera_rotation_mujoco(tilt_deg: float) -> np.ndarray:
    """World-from-camera rotation of the MuJoCo camera: looking straight down, tilted about x."""
    t = math.radians(tilt_deg)
    return np.array([[1.0, 0, 0], [0, math.cos(t), -math.sin(t)], [0, math.sin(t), math.cos(t)]])


def world_from_camera_cv(position: np.ndarray, rotation_mujoco: np.ndarray) -> np.ndarray:
    """4 x 4 pose of the OpenCV camera frame in the world, from a MuJoCo camera's pose."""
    pose = np.eye(4)
    pose[:3, :3] = rotation_mujoco @ MUJOCO_TO_OPENCV
    pose[:3, 3] = position
    return pose


def project(points_world: np.ndarray, world_from_camera: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Pixel coordinates (u, v) and depth z of world points, shape (N, 3)."""
    camera_from_world = np.linalg.inv(world_from_camera)
    pts = np.asarray(points_world, dtype=float) @ camera_from_world[:3, :3].T + camera_from_world[:3, 3]
    z = pts[:, 2]
    u = intrinsics.fx * pts[:, 0] / z + intrinsics.cx
    v = intrinsics.fy * pts[:, 1] / z + intrinsics.cy
    return np.stack([u, v, z], axis=1)
