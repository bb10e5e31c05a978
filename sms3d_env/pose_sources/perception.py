"""The ``"perception"`` pose source: the two-stage pipeline on the overhead camera's RGB-D.

At reset the scene is rendered from its overhead camera (RGB, metric depth, instance labels),
the detector's masks are cut out of the image, and the shipped axis CNN estimates each stem axis.
By default the masks are the shipped RGB-D segmenter's; the target's estimate is the one whose
mask overlaps the target's visible mask best, with IoU >= 0.5 (a missed target is a fallback
like an unestimated one). With ``detector="oracle"`` the masks come from MuJoCo's segmentation
render, so that only stage 2's error reaches the picker (an ablation).

If the target gets no estimate (hidden, or fewer points than the network needs) the source
falls back to an upright stem through the target's cap top — a flagged outcome, counted in
``fallbacks`` — rather than failing the episode before the robot moves.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from sms3d_env.pose_sources.base import PoseEstimate

MIN_TARGET_IOU = 0.5


def _target_estimate(estimates: list[Any], target_mask: np.ndarray) -> list[Any]:
    """The estimate whose mask overlaps ``target_mask`` best (IoU >= ``MIN_TARGET_IOU``), or none."""
    best, best_iou = None, MIN_TARGET_IOU
    from perception.detection.detector import mask_iou

    for est in estimates:
        iou = mask_iou(est.detection.mask, target_mask)
        if iou >= best_iou:
            best, best_iou = est, iou
    return [] if best is None else [best]


class PerceptionPose:
    """Callable pose source ``(scene, instance_id, rng) -> PoseEstimate`` using ``PosePipeline``.

    Args:
        pipeline: a ``perception.pipeline.PosePipeline``; default: the shipped pipeline
            (``PosePipeline.shipped``: the shipped axis CNN) behind ``detector``. A pipeline without a detector (``detector=None``) gets oracle masks.
        detector: stage 1 when no ``pipeline`` is given: ``"shipped"`` (default), ``"oracle"`` or
            a checkpoint path (``perception.detection.load.load_detector``).
        part: which oracle masks feed the network, ``"mushroom"`` (whole visible mushroom, what
            the shipped network was trained on) or ``"cap"``.
        realism: render the overhead frame with every camera and scene realism effect
            (``RealismOptions.all_on()``: stereo noise and shadows, flying pixels, RGB noise,
            lighting, camera jitter; docs/physics.md), drawn from the episode's ``rng``.
    """

    def __init__(self, pipeline: Any = None, part: Literal["cap", "mushroom"] = "mushroom",
                 detector: str = "shipped", realism: bool = False) -> None:
        if part not in ("cap", "mushroom"):
            raise ValueError(f"part must be 'cap' or 'mushroom', got {part!r}")
        self.pipeline = pipeline
        self.detector = detector
        self.realism = realism
        self.part = part
        self.fallbacks = 0
        self.last_axis_error_deg: float | None = None
        self.last_cap_top_error_mm: float | None = None
        self._renderer: Any = None

    def _pipeline(self) -> Any:
        if self.pipeline is None:
            from perception.pipeline import PosePipeline

            self.pipeline = PosePipeline.shipped(self.detector)
        return self.pipeline

    def __call__(self, scene: Any, instance_id: int, rng: np.random.Generator) -> PoseEstimate:
        from generator.dataset.render import SceneRenderer
        from perception.detection.detector import detections_from_labels

        cam = scene.config.camera
        if self._renderer is None or (self._renderer.height, self._renderer.width) != (cam.height, cam.width):
            self.close()
            self._renderer = SceneRenderer(cam.height, cam.width)
        if self.realism:
            from generator.dataset.options import DatasetOptions, RealismOptions

            # A child stream: the episode's own draws after this one do not depend on the effects.
            camera_rng = np.random.default_rng(rng.integers(2**63))
            frame = self._renderer.render(scene, DatasetOptions(realism=RealismOptions.all_on()), camera_rng,
                                          amodal=False)
        else:
            frame = self._renderer.render(scene, amodal=False)
        labels = frame.labels_cap if self.part == "cap" else frame.labels_mushroom
        pipeline = self._pipeline()
        if pipeline.detector is None:
            detections = [d for d in detections_from_labels(labels) if d.instance_id == instance_id]
            estimates = pipeline(frame.rgb, frame.depth, frame.intrinsics, frame.world_from_camera, detections)
        else:
            estimates = _target_estimate(
                pipeline(frame.rgb, frame.depth, frame.intrinsics, frame.world_from_camera), labels == instance_id + 1)
        truth = scene.instances[instance_id]
        if not estimates:
            self.fallbacks += 1
            self.last_axis_error_deg = float(np.degrees(np.arccos(np.clip(truth.stem_axis[2], -1, 1))))
            self.last_cap_top_error_mm = 0.0  # the fallback keeps the true cap top
            return PoseEstimate(np.asarray(truth.cap_top, float).copy(), np.eye(3))
        est = estimates[0]
        cos = float(np.clip(est.stem_axis_world @ truth.stem_axis, -1.0, 1.0))
        self.last_axis_error_deg = float(np.degrees(np.arccos(cos)))
        self.last_cap_top_error_mm = 1000 * float(np.linalg.norm(est.cap_top_world - truth.cap_top))
        return PoseEstimate(est.cap_top_world, est.rotation_world)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None  # GL contexts do not pickle; a copy renders with its own
        return state
