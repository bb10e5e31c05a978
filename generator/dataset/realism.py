"""Seeded realism: a RealSense-like stereo depth camera (D405/D435), RGB sensor effects,
lighting, soil and camera jitter. Facts, formulas and sources: docs/physics.md (cameras).

Model edits (lighting, soil, camera) act on a compiled ``MjModel`` before rendering; depth edits
act on the metric depth image, RGB edits on the rendered image. Each returns the values it drew,
recorded in ``scene.json``.

Draw order and reproducibility: an effect that is off draws nothing from the rng and records
nothing, so a dataset made with only the older options (``depth_noise``, ``edge_holes``,
``lighting``, ``soil``, ``camera_jitter``) is byte for byte what it was before the camera model
was added. The renderer calls ``randomise_model``, then ``apply_depth_realism``, then
``apply_rgb_realism``: switching an RGB effect does not change the depth draws.
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


def _depth_edges(depth: np.ndarray, threshold: float) -> np.ndarray:
    """Pixels whose depth differs from one of their 4 neighbours (0 = invalid counts) by more
    than ``threshold``, dilated by 1 px (the ``edge_holes`` edge)."""
    padded = np.pad(depth, 1, mode="edge")
    step = np.zeros_like(depth)
    for dv, du in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        neighbour = padded[1 + dv:1 + dv + depth.shape[0], 1 + du:1 + du + depth.shape[1]]
        step = np.maximum(step, np.abs(depth - neighbour))
    return cv2.dilate((step > threshold).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0


def _near_far(depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the least and greatest valid depth among itself and its 4 neighbours (the
    pixel's own depth where it has no valid neighbour)."""
    h, w = depth.shape
    valid = depth > 0
    pad = np.pad(np.where(valid, depth, np.nan), 1, constant_values=np.nan)
    stack = np.stack([pad[1 + dv:1 + dv + h, 1 + du:1 + du + w]
                      for dv, du in ((0, 0), (0, 1), (1, 0), (0, -1), (-1, 0))])
    with np.errstate(invalid="ignore"):
        near = np.fmin.reduce(stack, axis=0)
        far = np.fmax.reduce(stack, axis=0)
    return np.where(valid, near, 0.0), np.where(valid, far, 0.0)


def stereo_shadow_mask(depth: np.ndarray, focal_px: float, baseline_m: float, *,
                       left_band: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of a left-imager depth image that the right imager cannot see.

    A left pixel ``u`` with disparity ``d(u) = f B / z(u)`` appears in the right image at column
    ``u - d(u)``; it is occluded when a pixel ``u' > u`` of the same row lands at or left of it,
    ``u' - d(u') <= u - d(u)`` (such a pixel is necessarily nearer). A running minimum of
    ``u - d`` from the right finds this exactly, row by row. Returns ``(occluded, outside)``:
    ``outside`` (only if ``left_band``) marks points that land left of the right image,
    ``u - d(u) < -0.5``: the invalid band along the image's left edge. Invalid pixels (0) have
    ``d = 0`` and occlude nothing; neither mask contains them."""
    valid = depth > 0
    disparity = np.where(valid, focal_px * baseline_m / np.where(valid, depth, 1.0), 0.0)
    right_col = np.arange(depth.shape[1], dtype=np.float64)[None, :] - disparity
    min_right = np.minimum.accumulate(right_col[:, ::-1], axis=1)[:, ::-1]  # min over u' >= u
    min_strict = np.concatenate([min_right[:, 1:], np.full((depth.shape[0], 1), np.inf)], axis=1)
    occluded = valid & (min_strict <= right_col)
    outside = valid & (right_col < -0.5) & ~occluded if left_band else np.zeros_like(valid)
    return occluded, outside


def correlated_unit_noise(shape: tuple[int, int], window_px: int, rng: np.random.Generator) -> np.ndarray:
    """A zero-mean field of unit per-pixel std, correlated over ``window_px`` x ``window_px``:
    the mean of N(0, 1) white noise over the box around each pixel, times ``window_px``.

    The white noise is drawn with a margin of ``window_px - 1`` so that every output pixel
    averages a full box (no border effect). Neighbours ``k`` pixels apart along a row or column
    correlate by ``max(0, 1 - k / window_px)``."""
    h, w = shape
    white = rng.standard_normal((h + window_px - 1, w + window_px - 1))
    if window_px == 1:
        return white
    c = np.zeros((white.shape[0] + 1, white.shape[1] + 1))
    c[1:, 1:] = white.cumsum(0).cumsum(1)
    k = window_px
    box = c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]
    return box / k


def apply_depth_realism(depth: np.ndarray, focal_px: float, preset: str, options: RealismOptions,
                        rng: np.random.Generator) -> tuple[np.ndarray, dict[str, Any]]:
    """The stereo depth camera model on a metric (planar z) depth image; 0 stays invalid.

    Returns the new float32 depth and what the camera-model effects drew (the older
    ``depth_noise`` and ``edge_holes`` record nothing, as before). Steps, each only if on:

    1. ``stereo_shadows``: 0 where the right imager cannot see the point (``stereo_shadow_mask``),
       from the true depth;
    2. ``flying_pixels``: each pixel on a depth edge (a valid 4-neighbour more than
       ``edge_threshold`` away) becomes, with ``flying_pixel_probability``, ``near + a (far - near)``,
       ``a ~ U(0, 1)``, with near and far the extremes of itself and its valid 4-neighbours;
    3. noise, applied once: ``correlated_noise`` adds to the disparity ``d = f B / z`` a field of
       std ``depth_noise_subpixel`` px correlated over ``matching_window_px`` and sets
       ``z = f B / (d + n)``, so that ``sigma_z ~= z^2 s / (f B)``; otherwise ``depth_noise``
       adds white ``N(0, sigma_z^2)`` in depth, as before;
    4. ``edge_holes``, as before;
    5. ``disparity_quantisation``: ``z = f B / (step * round(d / step))``.
    """
    depth = depth.astype(np.float64, copy=True)
    valid = depth > 0
    baseline = STEREO_BASELINE_M[preset]
    fb = focal_px * baseline
    drawn: dict[str, Any] = {}
    if options.stereo_shadows:
        occluded, outside = stereo_shadow_mask(depth, focal_px, baseline, left_band=options.stereo_shadows_left_band)
        depth[occluded | outside] = 0.0
        drawn["stereo_shadows"] = {"baseline_m": baseline, "focal_px": float(focal_px),
                                   "occluded_pixels": int(occluded.sum()), "left_band_pixels": int(outside.sum())}
    if options.flying_pixels:
        near, far = _near_far(depth)
        candidates = (depth > 0) & ((far - depth > options.edge_threshold) | (depth - near > options.edge_threshold))
        pick = rng.random(depth.shape) < options.flying_pixel_probability
        alpha = rng.random(depth.shape)
        mixed = candidates & pick
        depth = np.where(mixed, near + alpha * (far - near), depth)
        drawn["flying_pixels"] = {"probability": options.flying_pixel_probability,
                                  "edge_pixels": int(candidates.sum()), "pixels": int(mixed.sum())}
    if options.correlated_noise:
        noisy = depth > 0
        field = options.depth_noise_subpixel * correlated_unit_noise(depth.shape, options.matching_window_px, rng)
        disparity = np.where(noisy, fb / np.where(noisy, depth, 1.0), 0.0) + field
        lost = noisy & (disparity <= 0)
        depth = np.where(noisy & ~lost, fb / np.where(disparity > 0, disparity, 1.0), 0.0)
        drawn["correlated_noise"] = {
            "subpixel_px": options.depth_noise_subpixel, "window_px": options.matching_window_px,
            "realised_std_px": float(field[noisy].std()) if noisy.any() else 0.0,
            "pixels": int(noisy.sum()), "invalidated_pixels": int(lost.sum()),
            "replaces_depth_noise": bool(options.depth_noise)}
    elif options.depth_noise:
        sigma = depth**2 * options.depth_noise_subpixel / fb
        depth = np.where(valid, depth + sigma * rng.standard_normal(depth.shape), 0.0)
    if options.edge_holes:
        edges = _depth_edges(depth, options.edge_threshold)
        holes = edges & (rng.random(depth.shape) < options.edge_hole_probability)
        depth[holes] = 0.0
    if options.disparity_quantisation:
        step = options.disparity_step_px
        ok = depth > 0
        levels = np.rint(np.where(ok, fb / np.where(ok, depth, 1.0), 0.0) / step)
        lost = ok & (levels <= 0)
        depth = np.where(ok & ~lost, fb / (np.where(levels > 0, levels, 1.0) * step), 0.0)
        drawn["disparity_quantisation"] = {"step_px": step, "pixels": int((ok & ~lost).sum()),
                                           "levels": int(np.unique(levels[ok & ~lost]).size),
                                           "invalidated_pixels": int(lost.sum())}
    depth[~valid] = 0.0
    return np.clip(depth, 0.0, None).astype(np.float32), drawn


def apply_rgb_realism(rgb: np.ndarray, options: RealismOptions,
                      rng: np.random.Generator) -> tuple[np.ndarray, dict[str, Any]]:
    """RGB sensor effects on an (H, W, 3) uint8 image; returns the new image and what was drawn.

    In the order light meets them: ``rgb_blur`` (optics: Gaussian, sigma ~ U(0,
    ``blur_sigma_max_px``)), ``exposure`` (gain ``2**U(-stops, +stops)``, clipped at 255 like a
    saturated pixel), ``rgb_noise`` (Poisson-Gaussian, approximated by a Gaussian of variance
    ``rgb_noise_gain * I + rgb_read_noise_dn**2`` in 8-bit DN, independent per pixel and
    channel), then rounding and clipping to uint8. With every RGB effect off the input comes
    back unchanged and nothing is drawn."""
    drawn: dict[str, Any] = {}
    if not options.rgb_any:
        return rgb, drawn
    img = rgb.astype(np.float64)
    if options.rgb_blur:
        sigma = float(rng.uniform(0.0, options.blur_sigma_max_px))
        if sigma > 1e-3:
            img = cv2.GaussianBlur(img, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT)
        drawn["rgb_blur"] = {"sigma_px": sigma}
    if options.exposure:
        stops = float(rng.uniform(-options.exposure_stops, options.exposure_stops))
        gain = 2.0**stops
        img = img * gain
        drawn["exposure"] = {"stops": stops, "gain": gain, "saturated_fraction": float((img > 255.0).mean())}
        img = np.minimum(img, 255.0)
    if options.rgb_noise:
        signal = np.clip(img, 0.0, 255.0)
        std = np.sqrt(options.rgb_noise_gain * signal + options.rgb_read_noise_dn**2)
        img = signal + std * rng.standard_normal(img.shape)
        drawn["rgb_noise"] = {"gain": options.rgb_noise_gain, "read_noise_dn": options.rgb_read_noise_dn,
                              "mean_std_dn": float(std.mean())}
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), drawn
