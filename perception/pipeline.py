"""The two-stage pose pipeline: masks from a detector, then each mushroom's stem axis from the
axis CNN (shipped) or a point network (the baseline) and its cap top from its points.
``(rgb, depth, intrinsics, world_from_camera) -> [MushroomEstimate]``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from generator.camera import Intrinsics
from perception.detection.detector import Detection, Detector
from perception.errors import NoEstimate, PerceptionConfigError, PipelineInputError
from perception.pointcloud import (
    MIN_POINTS,
    check_cloud,
    check_metres,
    depth_to_points,
    pinhole_intrinsics,
)
from perception.pose.axis_cnn import AxisCNNEstimator, rotation_from_axis

if TYPE_CHECKING:  # the baseline's estimator is loaded only by those who pass one
    from perception.baselines.point_transformer.estimator import PoseEstimator

#: The cloud's top along the axis is this percentile of the points' heights (robust to strays).
CAP_TOP_PERCENTILE = 99.0
#: The dome is fitted to the points within this distance (m) below the cloud's top along the axis.
CAP_TOP_FIT_BAND_M = 12e-3
#: Points whose residual exceeds this many robust standard deviations are down-weighted.
CAP_TOP_HUBER = 2.0
#: The fallback's band: points within this distance (m) below the top, when no dome fits.
CAP_TOP_BAND_M = 1e-3


def estimate_cap_top(points: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The cap's apex from a mushroom's observed ``points (N, 3)`` (metres) and its unit stem
    ``axis``: where a picker aims.

    The apex is where the cap's surface is highest along the axis. The top of the cap within
    ``CAP_TOP_FIT_BAND_M`` of the cloud's top (its ``CAP_TOP_PERCENTILE`` height) is fitted,
    by least squares reweighted against strays (Huber, ``CAP_TOP_HUBER``), with a paraboloid of
    revolution about the axis, ``h = c + b . (u, v) + d |(u, v)|^2``; its stationary point is
    the apex. Every point of the band tells where the dome peaks, so a depth camera's noise
    averages out instead of deciding which few points are highest. Where no dome fits (``d >=
    0``, fewer than 10 points, or a peak outside the band's reach) the apex is the centroid of
    the points within ``CAP_TOP_BAND_M`` of the top, raised to it.

    Measured on the 50 held-out 40-mushroom beds of each camera (the shipped segmenter and the
    point network; docs/results-perception.md), mean distance to the true apex: 8.2 → 6.7 mm with
    ``--realism``, 4.6 → 4.3 mm clean, against the top-band centroid. What remains follows the axis error: a dome's apex
    along a wrong axis is where the surface faces that axis.
    """
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    points = np.asarray(points, dtype=np.float64)
    heights = points @ axis
    top = np.percentile(heights, CAP_TOP_PERCENTILE)
    fitted = _fit_dome_apex(points[heights >= top - CAP_TOP_FIT_BAND_M], axis)
    if fitted is not None:
        return fitted
    band = heights >= top - CAP_TOP_BAND_M
    return points[band].mean(0) + axis * (top - heights[band].mean())


def _fit_dome_apex(points: np.ndarray, axis: np.ndarray) -> np.ndarray | None:
    """The stationary point of a robust paraboloid fit about ``axis`` (see
    :func:`estimate_cap_top`), or ``None`` where the points do not make a dome."""
    if len(points) < 10:
        return None
    u_dir, v_dir = rotation_from_axis(axis)[:, :2].T
    centre = points.mean(0)
    rel = points - centre
    u, v, h = rel @ u_dir, rel @ v_dir, rel @ axis
    design = np.stack([np.ones_like(u), u, v, u * u + v * v], 1)
    weights = np.ones(len(u))
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(design * weights[:, None], h * weights, rcond=None)
        residual = h - design @ coef
        scale = 1.4826 * np.median(np.abs(residual)) + 1e-9
        weights = 1.0 / np.sqrt(np.maximum(1.0, np.abs(residual) / (CAP_TOP_HUBER * scale)))
    c, b_u, b_v, d = coef
    if d >= 0:
        return None
    peak_u, peak_v = -b_u / (2 * d), -b_v / (2 * d)
    if np.hypot(peak_u, peak_v) > np.sqrt(u * u + v * v).max():
        return None
    peak_h = c + b_u * peak_u + b_v * peak_v + d * (peak_u**2 + peak_v**2)
    return centre + peak_u * u_dir + peak_v * v_dir + peak_h * axis


@dataclass(frozen=True)
class MushroomEstimate:
    """One mushroom's estimated pose in the camera frame (OpenCV axes) and in the world."""

    detection: Detection
    rotation_cam: np.ndarray  # (3, 3) camera-from-mushroom
    centre_cam: np.ndarray  # centroid of the mushroom's observed points
    cap_top_cam: np.ndarray  # the cap's apex (estimate_cap_top): where a picker aims
    rotation_world: np.ndarray
    centre_world: np.ndarray
    cap_top_world: np.ndarray
    num_points: int

    @property
    def stem_axis_cam(self) -> np.ndarray:
        return self.rotation_cam[:, 2].copy()

    @property
    def stem_axis_world(self) -> np.ndarray:
        return self.rotation_world[:, 2].copy()


def check_inputs(rgb: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics | np.ndarray,
                 world_from_camera: np.ndarray) -> None:
    """Raise ``PipelineInputError`` for inputs that would otherwise fail deep inside torch, and
    ``PerceptionConfigError`` naming the field for intrinsics that are no pinhole camera
    (``pinhole_intrinsics``; a 3x3 ``K`` is one, without an image size to compare)."""
    rgb, depth = np.asarray(rgb), np.asarray(depth)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise PipelineInputError(f"rgb: expected (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
    if depth.shape != rgb.shape[:2]:
        raise PipelineInputError(f"depth: shape {depth.shape} differs from the image's {rgb.shape[:2]}")
    if not np.issubdtype(depth.dtype, np.floating):
        raise PipelineInputError(f"depth: expected float metres, got {depth.dtype} (divide millimetres by 1000)")
    pinhole_intrinsics(intrinsics)
    if hasattr(intrinsics, "width") and (intrinsics.width, intrinsics.height) != (rgb.shape[1], rgb.shape[0]):
        raise PipelineInputError(f"intrinsics are for {intrinsics.width}x{intrinsics.height}, the image is "
                                 f"{rgb.shape[1]}x{rgb.shape[0]}")
    check_metres(depth, "depth")
    pose = np.asarray(world_from_camera, dtype=float)
    if pose.shape != (4, 4) or not np.allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-6):
        raise PipelineInputError("world_from_camera: expected a 4 x 4 rigid transform")


def above_soil(mask: np.ndarray, depth: np.ndarray, margin_m: float, ring_px: int = 6) -> np.ndarray:
    """``mask`` without the pixels that lie at the local soil depth.

    A learned mask that spills over a mushroom's silhouette adds soil points, which tilt the
    pose network's estimate. The soil depth is the median valid depth in a ring ``ring_px`` wide
    around the mask; pixels deeper than that minus ``margin_m`` are dropped. Without valid depth
    in the ring the mask is returned unchanged.
    """
    ring = cv2.dilate(mask.astype(np.uint8), np.ones((2 * ring_px + 1,) * 2, np.uint8)).astype(bool) & ~mask
    around = depth[ring]
    around = around[np.isfinite(around) & (around > 0)]
    if around.size == 0:
        return mask
    return mask & (depth < float(np.median(around)) - margin_m)


def within_depth_of_core(mask: np.ndarray, depth: np.ndarray, tolerance_m: float, core_px: int = 2) -> np.ndarray:
    """``mask`` without the border pixels that lie more than ``tolerance_m`` deeper than the
    mask's interior beside them.

    A learned mask that spills one or two pixels over a cap's rim adds soil points centimetres
    below it (the shipped segmenter decodes at half resolution: on fully visible caps of the
    clean held-out beds ~35 spilled and ~36 missing pixels of ~1,700). Here the interior is the
    mask eroded by ``core_px``; a border pixel is kept when its valid depth is at most
    ``tolerance_m`` beyond the deepest interior depth within ``core_px + 1`` pixels of it, so a
    cap's own rim (which falls away by millimetres) stays and the soil beyond it goes, however
    close the soil is to the cap elsewhere (which ``above_soil``'s ring cannot tell). Parts too
    thin to have an interior beside them (a sliver of a cap between its neighbours) have
    nothing to be judged by and stay — so does a lobe of soil reaching more than ``core_px + 1``
    pixels beyond the interior, the price of keeping slivers. Pixels without valid depth (0, NaN,
    inf) add no points to a cloud and are kept. A mask with fewer than ``MIN_POINTS`` interior
    pixels is returned unchanged.
    """
    core = cv2.erode(mask.astype(np.uint8), np.ones((2 * core_px + 1,) * 2, np.uint8)).astype(bool)
    valid = np.isfinite(depth) & (depth > 0)
    if np.count_nonzero(core & valid) < MIN_POINTS:
        return mask
    interior = np.where(core & valid, depth, 0.0).astype(np.float32)
    deepest = cv2.dilate(interior, np.ones((2 * core_px + 3,) * 2, np.uint8))
    border = mask & ~core & (~valid | (deepest == 0) | (depth <= deepest + tolerance_m))
    return core | border


class PosePipeline:
    """Detector + pose network.

    ``detector`` is a ``Detector``, or a name for ``perception.detection.load.load_detector``:
    ``"shipped"`` (the default: the RGB-D segmenter shipped with the package, loaded at first
    use), ``"oracle"`` / ``None`` (no detector: masks are passed to each call, e.g. MuJoCo's
    segmentation), or a checkpoint path.

    ``soil_margin_m`` drops mask pixels within that distance of the local soil depth (see
    ``above_soil``; ``None``, the default, keeps masks whole). It helps a pose network trained on
    exact masks that is given learned ones (CPU-trained Mask R-CNN: 34° -> 14° mean stem-axis
    error; the shipped segmenter with a point network trained on exact masks: 30° -> 10°, 6 mm),
    but not the shipped point network, which was trained on the segmenter's masks (9.5° -> 9.8°
    clean, and recall 0.973 -> 0.944). ``edge_tolerance_m`` drops border pixels deeper than the mask's interior
    beside them by more than that (``within_depth_of_core``; ``None``, the default, keeps masks
    whole). Measured on the 50 clean held-out beds at 10 mm with point networks: it helps
    fully visible caps (6.9° -> 5.0° mean stem-axis error; a network trained on exact masks,
    30° -> 8.9° overall) and hurts occluded ones (21.5° -> 23.9° below
    half visible), 9.0° -> 8.7° in all; under the camera model 15.7° -> 17.7°, so it is off by
    default. ``erode_px`` trims mask borders; it
    is 0 by default because the shipped network was fine-tuned on un-eroded masks (1 px of erosion
    raised its error with exact masks from 9.2° to 12.5°).

    ``depth_smoothing_px`` smooths each mask's depth before its points are taken
    (:func:`~perception.baselines.point_transformer.depth_smoothing.smooth_depth_in_mask`); ``None``, the default, takes it
    from the network (``estimator.config.depth_smoothing_px``): a network is fed as it was trained.

    ``axis_model`` (an :class:`~perception.pose.axis_cnn.AxisCNNEstimator`) reads each stem axis
    from an RGB-D crop around the whole, untrimmed mask (as it was trained) instead of the point
    network; ``estimator`` may then be ``None`` (with neither, the pipeline only trims masks and
    refuses to estimate). The rotation's yaw about the axis is arbitrary; the centre and the cap
    top still come from the (trimmed) mask's points. :meth:`shipped` builds the pipeline the
    package ships: the shipped segmenter and the shipped axis CNN.
    """

    def __init__(self, estimator: PoseEstimator | None, detector: Detector | str | None = "shipped", erode_px: int = 0,
                 soil_margin_m: float | None = None, edge_tolerance_m: float | None = None,
                 depth_smoothing_px: float | None = None, axis_model: AxisCNNEstimator | None = None) -> None:
        self.estimator = estimator
        self.axis_model = axis_model
        self._detector = detector
        self.erode_px = erode_px
        self.soil_margin_m = soil_margin_m
        self.edge_tolerance_m = edge_tolerance_m
        self.depth_smoothing_px = depth_smoothing_px

    @classmethod
    def shipped(cls, detector: Detector | str | None = "shipped", **kwargs) -> PosePipeline:
        """The shipped pipeline: ``detector`` (default the shipped RGB-D segmenter) and the
        shipped axis CNN (``perception/weights/axis_cnn``); ``kwargs`` as for the constructor."""
        from perception.pose.axis_cnn import AxisCNNEstimator

        return cls(None, detector, axis_model=AxisCNNEstimator.from_pretrained(), **kwargs)

    @property
    def min_points(self) -> int:
        """Fewest valid points a mask needs for an estimate."""
        return self.estimator.min_points if self.estimator is not None else MIN_POINTS

    def trim_mask(self, mask: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """A detection's mask as the pose cloud is cut from it: eroded by ``erode_px``, then
        without soil pixels (``soil_margin_m``) and pixels beyond the interior's depth
        (``edge_tolerance_m``)."""
        if self.erode_px > 0:
            mask = cv2.erode(mask.astype(np.uint8), np.ones((2 * self.erode_px + 1,) * 2, np.uint8)).astype(bool)
        if self.soil_margin_m is not None:
            mask = above_soil(mask, depth, self.soil_margin_m)
        if self.edge_tolerance_m is not None:
            mask = within_depth_of_core(mask, depth, self.edge_tolerance_m)
        return mask

    def cloud_pixels(self, mask: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The mask and depth a detection's pose cloud is taken from: ``trim_mask``'s mask, and
        the depth smoothed inside it (``depth_smoothing_px``)."""
        mask = self.trim_mask(mask, depth)
        sigma = self.depth_smoothing_px
        if sigma is None:
            sigma = self.estimator.config.depth_smoothing_px if self.estimator is not None else 0.0
        if sigma <= 0:
            return mask, depth
        from perception.baselines.point_transformer.depth_smoothing import smooth_depth_in_mask

        return mask, smooth_depth_in_mask(depth, mask, sigma)

    @property
    def detector(self) -> Detector | None:
        """The stage-1 detector (``None``: masks must be passed in); a name is loaded here, once."""
        if isinstance(self._detector, str):
            from perception.detection.load import load_detector

            self._detector = load_detector(self._detector)
        return self._detector

    def __call__(self, rgb: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics | np.ndarray,
                 world_from_camera: np.ndarray, detections: list[Detection] | None = None) -> list[MushroomEstimate]:
        """Estimates for every detection with enough valid points (others are left out: a
        too-small or empty mask, or one whose points lie on a line, gives no estimate, never
        NaN). Pass ``detections`` to skip the detector (e.g. oracle masks from
        ``detections_from_labels``); ``intrinsics`` may be a 3x3 camera matrix."""
        if self.estimator is None and self.axis_model is None:
            raise PerceptionConfigError("estimator", "this pipeline only trims masks: give it a pose estimator or "
                                                     "an axis_model to estimate")
        check_inputs(rgb, depth, intrinsics, world_from_camera)
        if detections is None:
            if self.detector is None:
                raise ValueError("no detector: pass detections, or build the pipeline with a detector")
            detections = self.detector.detect(rgb, depth)
        world_from_camera = np.asarray(world_from_camera, dtype=float)
        clouds, colours, kept = [], [], []
        for det in detections:
            mask, cloud_depth = self.cloud_pixels(det.mask, depth)
            points, colors = depth_to_points(cloud_depth, intrinsics, mask, rgb)
            try:
                check_cloud(points, self.min_points)
            except NoEstimate:
                continue
            clouds.append(points.astype(np.float64))
            colours.append(colors)
            kept.append(det)
        if not clouds:
            return []
        if self.axis_model is not None:
            axes = self.axis_model.estimate_axes(rgb, depth, [det.mask for det in kept], intrinsics)
            found = [(det, points, rotation_from_axis(axis), points.mean(0), len(points))
                     for det, points, axis in zip(kept, clouds, axes) if axis is not None]
        else:
            # Every cloud passed check_cloud above, so this raises no NoEstimate.
            estimates = self.estimator.estimate_batch(clouds, colours if self.estimator.config.use_rgb else None)
            found = [(det, points, est.rotation, est.centre, est.num_points)
                     for det, points, est in zip(kept, clouds, estimates)]
        rot, trans = world_from_camera[:3, :3], world_from_camera[:3, 3]
        results = []
        for det, points, rotation, centre, num_points in found:
            top = estimate_cap_top(points, rotation[:, 2])
            results.append(MushroomEstimate(
                detection=det, rotation_cam=rotation, centre_cam=centre, cap_top_cam=top,
                rotation_world=rot @ rotation, centre_world=rot @ centre + trans,
                cap_top_world=rot @ top + trans, num_points=num_points,
            ))
        return results
