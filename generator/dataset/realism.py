"""Seeded realism: RealSense-like depth noise and edge holes, lighting, soil and camera jitter.

Model edits (lighting, soil, camera) act on a compiled ``MjModel`` before rendering; depth edits
act on the metric depth image. Each returns the values it drew, recorded in ``scene.json``.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import mujoco
import numpy as np

from generator.dataset.options import STEREO_BASELINE_M, RealismOptions
from generator.geometry import axis_angle_matrix


def randomise_model(model: mujoco.MjModel, options: RealismOptions, rng: np.random.Generator) -> dict[str, Any]:
    """Apply lighting, soil and camera jitter to ``model`` in place; return what was drawn."""
    drawn: dict[str, Any] = {}
    if options.lighting:
        gains = rng.uniform(0.6, 1.4, size=model.nlight)
        for i in range(model.nlight):
            model.light_diffuse[i] = np.clip(model.light_diffuse[i] * gains[i], 0, 1)
            model.light_pos[i, :2] += rng.uniform(-0.3, 0.3, size=2)
            d = model.light_dir[i] + np.append(rng.uniform(-0.3, 0.3, size=2), 0.0)
            model.light_dir[i] = d / np.linalg.norm(d)
        ambient = float(rng.uniform(0.2, 0.5))
        model.vis.headlight.ambient[:] = ambient
        drawn["lighting"] = {"diffuse_gain": gains.tolist(), "ambient": ambient}
    if options.soil:
        mat = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_MATERIAL, "soil")
        tint = np.clip(rng.uniform(0.75, 1.0) * rng.uniform(0.9, 1.1, size=3), 0, 1)
        repeat = float(rng.uniform(1.0, 3.0))
        model.mat_rgba[mat, :3] = tint
        model.mat_texrepeat[mat] = repeat
        drawn["soil"] = {"tint": tint.tolist(), "texrepeat": repeat}
    if options.camera_jitter:
        cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "overhead")
        dz = float(rng.uniform(-options.camera_height_jitter, options.camera_height_jitter))
        phi = float(rng.uniform(0, 2 * math.pi))
        tilt = math.radians(float(rng.uniform(0, options.camera_tilt_jitter_deg)))
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.cam_quat[cam])
        rot = axis_angle_matrix(np.array([math.cos(phi), math.sin(phi), 0.0]), tilt) @ rot.reshape(3, 3)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, rot.ravel())
        model.cam_pos[cam, 2] += dz
        model.cam_quat[cam] = quat
        drawn["camera"] = {"height_offset": dz, "tilt_axis_angle_deg": math.degrees(phi),
                           "tilt_deg": math.degrees(tilt)}
    return drawn


def apply_depth_realism(depth: np.ndarray, focal_px: float, preset: str, options: RealismOptions,
                        rng: np.random.Generator) -> np.ndarray:
    """Stereo noise ``sigma_z = z^2 s / (f B)`` and holes at depth edges; 0 stays invalid."""
    depth = depth.astype(np.float64, copy=True)
    valid = depth > 0
    if options.depth_noise:
        sigma = depth**2 * options.depth_noise_subpixel / (focal_px * STEREO_BASELINE_M[preset])
        depth = np.where(valid, depth + sigma * rng.standard_normal(depth.shape), 0.0)
    if options.edge_holes:
        padded = np.pad(depth, 1, mode="edge")
        step = np.zeros_like(depth)
        for dv, du in ((0, 1), (1, 0), (0, -1), (-1, 0)):
            neighbour = padded[1 + dv:1 + dv + depth.shape[0], 1 + du:1 + du + depth.shape[1]]
            step = np.maximum(step, np.abs(depth - neighbour))
        edges = cv2.dilate((step > options.edge_threshold).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        holes = edges & (rng.random(depth.shape) < options.edge_hole_probability)
        depth[holes] = 0.0
    depth[~valid] = 0.0
    return np.clip(depth, 0.0, None).astype(np.float32)
