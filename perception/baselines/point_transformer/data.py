"""Per-mushroom point-cloud samples, their ``.npz`` file format and a torch ``Dataset``.

File format (``numpy.savez_compressed``, no pickles), ``K`` instances, ``M`` points in all:

===============  ==================  ===================================================
``points``       float32 ``(M, 3)``  camera-frame points (m, OpenCV), instances concatenated
``offsets``      int64 ``(K + 1,)``  instance ``i`` is ``points[offsets[i]:offsets[i+1]]``
``rotations``    float32 ``(K,3,3)`` camera-from-mushroom rotation; column 2 = stem axis
``colors``       float32 ``(M, 3)``  optional, RGB in [0, 1]
``meta``         0-d str             JSON list of ``K`` dicts (species, size, angles, ...)
``version``      int64 scalar        :data:`FORMAT_VERSION`
===============  ==================  ===================================================
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from perception.baselines.point_transformer.augment import (
    AugmentConfig,
    augment_points,
    occlude_points,
)
from perception.detection.detector import matched_detections
from perception.errors import PerceptionConfigError
from perception.pointcloud import MIN_POINTS, SamplingMethod, prepare_cloud, to_tensor
from perception.run_files import checksum

FORMAT_VERSION = 1


class DatasetFormatError(ValueError):
    """A point-cloud ``.npz`` file that does not follow the documented format."""


@dataclass(frozen=True)
class PointCloudSample:
    """One mushroom seen by the camera."""

    points: np.ndarray  # (N, 3) float32, camera frame, metres
    rotation: np.ndarray  # (3, 3) camera-from-mushroom; [:, 2] is the stem axis
    colors: np.ndarray | None = None  # (N, 3) float32 in [0, 1]
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        p = np.asarray(self.points)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points: expected shape (N, 3), got {p.shape}")
        if np.asarray(self.rotation).shape != (3, 3):
            raise ValueError(f"rotation: expected shape (3, 3), got {np.asarray(self.rotation).shape}")
        if self.colors is not None and np.asarray(self.colors).shape != p.shape:
            raise ValueError(f"colors: shape {np.asarray(self.colors).shape} differs from points {p.shape}")


def save_samples(path: str | Path, samples: Sequence[PointCloudSample]) -> None:
    """Write ``samples`` in the documented ``.npz`` format."""
    if not samples:
        raise ValueError("samples: nothing to save")
    has_colors = all(s.colors is not None for s in samples)
    counts = np.array([len(s.points) for s in samples], dtype=np.int64)
    arrays: dict[str, Any] = {
        "points": np.concatenate([np.asarray(s.points, np.float32) for s in samples]),
        "offsets": np.concatenate(([0], np.cumsum(counts))).astype(np.int64),
        "rotations": np.stack([np.asarray(s.rotation, np.float32) for s in samples]),
        "meta": np.array(json.dumps([s.meta for s in samples])),
        "version": np.int64(FORMAT_VERSION),
    }
    if has_colors:
        arrays["colors"] = np.concatenate([np.asarray(s.colors, np.float32) for s in samples])
    np.savez_compressed(Path(path), **arrays)


def load_samples(path: str | Path) -> list[PointCloudSample]:
    """Read a file written by :func:`save_samples` (or by the dataset writer, same format)."""
    path = Path(path)
    try:
        z = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise DatasetFormatError(f"{path}: not a readable .npz file ({exc})") from exc
    with z:
        for key in ("points", "offsets", "rotations", "meta", "version"):
            if key not in z:
                raise DatasetFormatError(f"{path}: missing array {key!r}")
        if int(z["version"]) != FORMAT_VERSION:
            raise DatasetFormatError(f"{path}: version {int(z['version'])}, expected {FORMAT_VERSION}")
        points, offsets, rots = z["points"], z["offsets"], z["rotations"]
        colors = z["colors"] if "colors" in z else None
        meta = json.loads(str(z["meta"]))
    k = len(rots)
    if offsets.shape != (k + 1,) or offsets[-1] != len(points) or len(meta) != k:
        raise DatasetFormatError(f"{path}: offsets/rotations/meta lengths disagree")
    return [
        PointCloudSample(
            points[offsets[i] : offsets[i + 1]],
            rots[i],
            None if colors is None else colors[offsets[i] : offsets[i + 1]],
            meta[i],
        )
        for i in range(k)
    ]


class PointCloudPoseDataset(Dataset):
    """Network-ready items ``(x (num_points, 3|6) float32, rotation (3, 3) float32, index)``.

    Each item is filtered, sampled to ``num_points``, normalised into the unit sphere and (when
    ``augment`` is given) augmented. Randomness is drawn from
    ``default_rng([seed, epoch, index])``, so items are reproducible and independent of the
    worker layout; call :meth:`set_epoch` each epoch for fresh augmentation. Samples with fewer
    than :data:`~perception.pointcloud.MIN_POINTS` finite points are dropped on construction
    (``num_dropped`` counts them).
    """

    def __init__(
        self,
        samples: Sequence[PointCloudSample],
        num_points: int = 1024,
        use_rgb: bool = False,
        augment: AugmentConfig | None = None,
        seed: int = 0,
        sampling: SamplingMethod = "random",
    ) -> None:
        if num_points < MIN_POINTS:
            raise PerceptionConfigError("num_points", f"must be >= {MIN_POINTS}, got {num_points}")
        if use_rgb and any(s.colors is None for s in samples):
            raise PerceptionConfigError("use_rgb", "requested but some samples have no colors")
        keep = [s for s in samples if np.isfinite(np.asarray(s.points)).all(1).sum() >= MIN_POINTS]
        self.num_dropped = len(samples) - len(keep)
        self.samples = keep
        self.num_points, self.use_rgb, self.augment = num_points, use_rgb, augment
        self.seed, self.sampling, self.epoch = seed, sampling, 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def checksum(self) -> str:
        """What a training run records of its data (``run_files.checksum``): every sample's
        points, colours (when fed) and rotation, and the seed and sampling that draw from them."""
        fed = [a for s in self.samples for a in (s.points, s.rotation, *([s.colors] if self.use_rgb else []))]
        return checksum(*map(np.asarray, fed), np.array([self.seed]), np.array(self.sampling))

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, i: int) -> tuple[torch.Tensor, torch.Tensor, int]:
        s = self.samples[i]
        rng = np.random.default_rng([self.seed, self.epoch, i])
        points, colors = s.points, s.colors if self.use_rgb else None
        # Drawn only when occlusion is on, so that runs without it keep their random streams.
        if self.augment is not None and self.augment.occlusion_prob > 0 and rng.random() < self.augment.occlusion_prob:
            points, colors = occlude_points(np.asarray(points, np.float64), rng.uniform(*self.augment.occlusion_fraction),
                                            rng, colors)
        cloud = prepare_cloud(points, self.num_points, rng, colors, self.sampling)
        pts, cols = cloud.points, cloud.colors
        if self.augment is not None:
            pts, cols = augment_points(pts, self.augment, rng, cols)
        x = to_tensor(pts, cols)
        return x, torch.from_numpy(np.asarray(s.rotation, np.float32)), i


def samples_from_scenes(
    root: str | Path, split: str | None = None, num_points: int = 2048, cap_only: bool = False, seed: int = 0
) -> list[PointCloudSample]:
    """Per-instance samples from a rendered scene dataset (``generator.dataset`` layout).

    Wraps ``generator.dataset.readers.InstancePointCloudDataset``: points are back-projected
    under each instance's visible mask (whole mushroom, or the cap with ``cap_only``) and
    sampled to ``num_points``; rotations are in the OpenCV camera frame.
    """
    from generator.dataset.readers import InstancePointCloudDataset

    ds = InstancePointCloudDataset(root, split, num_points=num_points, cap_only=cap_only, min_points=MIN_POINTS, seed=seed)
    out = []
    for i in range(len(ds)):
        item = ds[i]
        meta = dict(item["meta"])
        out.append(PointCloudSample(item["points"].numpy(), item["rotation"].numpy(), None, meta))
    return out


def samples_from_detections(
    root: str | Path, split: str | None, detector: Any, num_points: int = 2048, seed: int = 0,
    min_iou: float = 0.5, progress: bool = False,
    cloud_pixels: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
) -> list[PointCloudSample]:
    """Per-instance samples cut out by a stage-1 ``detector``'s masks instead of the renderer's.

    Each scene's detections are matched to its ground-truth mushrooms by visible-mask IoU (>=
    ``min_iou``, best score first, one detection per mushroom); a matched detection's valid
    depth pixels become the sample's points, labelled with that mushroom's rotation. So the pose
    network learns from the masks it will be given: their soil pixels at the borders, their
    missing bits, the camera's noise. Unmatched detections and mushrooms are left out.
    ``cloud_pixels(mask, depth) -> (mask, depth)`` (e.g. ``PosePipeline.cloud_pixels``) trims each
    matched mask and smooths its depth as the pipeline will before its points are taken;
    matching uses the whole mask. Each sample carries its points' RGB (for ``use_rgb`` networks).
    """
    from generator.dataset.readers import instance_in_camera, read_scene_files, scene_indices
    from generator.dataset.writer import scene_dirname
    from generator.geometry import tilt_angle
    from perception.pointcloud import depth_to_points

    root = Path(root)
    indices = scene_indices(root, split)
    if progress:
        from tqdm import tqdm

        indices = tqdm(indices, desc=f"masks of {root.name}/{split}", unit="scene")
    out = []
    for index in indices:
        s = read_scene_files(root / scene_dirname(index), verify=False)
        for det, best, best_iou in matched_detections(detector.detect(s.rgb, s.depth), s.labels_mushroom, min_iou):
            mask, depth = (det.mask, s.depth) if cloud_pixels is None else cloud_pixels(det.mask, s.depth)
            points, colors = depth_to_points(depth, s.intrinsics, mask, s.rgb)
            if len(points) < MIN_POINTS:
                continue
            rng = np.random.default_rng(np.random.SeedSequence([seed, index, best]))
            pick = rng.choice(len(points), num_points, replace=len(points) < num_points)
            inst = next(m for m in s.record["instances"] if m["id"] == best)
            gt = instance_in_camera(inst, s.world_from_camera)
            meta = {"scene_id": index, "instance_id": best, "species": inst["species"],
                    "cap_diameter": inst["cap_diameter"], "num_valid": len(points), "mask_iou": best_iou,
                    "tilt_deg": float(np.degrees(tilt_angle(np.asarray(inst["rotation"]))))}
            out.append(PointCloudSample(points[pick].astype(np.float32), gt["rotation"].astype(np.float32),
                                        colors[pick], meta))
    return out
