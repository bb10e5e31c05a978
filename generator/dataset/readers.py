"""Read a generated dataset back: scene files with validation, and torch datasets for whole
scenes and for per-instance point clouds.

Every unreadable, truncated or altered file raises ``CorruptFileError`` naming it (files are
checked against the SHA-256 sums in the scene's ``DONE`` file unless ``verify=False``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from torch.utils.data import Dataset

from generator.camera import Intrinsics
from generator.dataset.backproject import backproject
from generator.dataset.coco import decode_mask
from generator.dataset.errors import CorruptFileError
from generator.dataset.writer import DEPTH_SCALE, DONE, FILES, scene_dirname
from generator.errors import SceneFormatError
from generator.geometry import tilt_angle
from generator.scene import Scene


@dataclass
class SceneSample:
    """One scene read from disk (numpy arrays; depth in metres, 0 = invalid)."""

    index: int
    rgb: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) float32 m
    labels_mushroom: np.ndarray  # (H, W) uint16
    labels_cap: np.ndarray  # (H, W) uint16
    amodal_caps: dict[int, np.ndarray]  # instance id -> (H, W) bool
    record: dict[str, Any]  # scene.json
    annotations: list[dict[str, Any]]  # this scene's COCO annotations

    @property
    def scene(self) -> Scene:
        return Scene.from_dict(self.record)

    @property
    def K(self) -> np.ndarray:  # noqa: N802
        return np.asarray(self.record["camera"]["K"], dtype=np.float64)

    @property
    def world_from_camera(self) -> np.ndarray:
        return np.asarray(self.record["camera"]["world_from_camera"], dtype=np.float64)

    @property
    def intrinsics(self) -> Intrinsics:
        k = self.record["camera"]["intrinsics"]
        return Intrinsics(**{name: k[name] for name in ("width", "height", "fx", "fy", "cx", "cy")})


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise CorruptFileError(path, f"cannot read ({exc.strerror or exc})") from exc


def _json(path: Path, data: bytes) -> Any:
    try:
        return json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise CorruptFileError(path, f"not valid JSON ({exc})") from exc


def _png(path: Path, data: bytes, dtype: type, channels: int, shape: tuple[int, int] | None) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if img is None:
        raise CorruptFileError(path, "not a readable PNG")
    if img.dtype != dtype or (img.ndim == 3) != (channels == 3) or (shape is not None and img.shape[:2] != shape):
        raise CorruptFileError(path, f"unexpected image {img.shape} {img.dtype}")
    return img


def read_scene_files(scene_dir: str | Path, verify: bool = True) -> SceneSample:
    """Read and validate one scene folder."""
    folder = Path(scene_dir)
    done_path = folder / DONE
    if not done_path.is_file():
        raise CorruptFileError(done_path, "missing: the scene was never completed")
    sums = _json(done_path, _read_bytes(done_path))
    raw = {}
    for name in FILES:
        raw[name] = _read_bytes(folder / name)
        if verify and hashlib.sha256(raw[name]).hexdigest() != sums.get(name):
            raise CorruptFileError(folder / name, "checksum differs from the one recorded in DONE")
    record = _json(folder / "scene.json", raw["scene.json"])
    try:
        h, w = int(record["camera"]["intrinsics"]["height"]), int(record["camera"]["intrinsics"]["width"])
        index = int(record["dataset"]["index"])
    except (KeyError, TypeError, ValueError) as exc:
        raise CorruptFileError(folder / "scene.json", f"missing camera or dataset entry ({exc})") from exc
    rgb = _png(folder / "rgb.png", raw["rgb.png"], np.uint8, 3, (h, w))
    depth = _png(folder / "depth.png", raw["depth.png"], np.uint16, 1, (h, w))
    lm = _png(folder / "labels_mushroom.png", raw["labels_mushroom.png"], np.uint16, 1, (h, w))
    lc = _png(folder / "labels_cap.png", raw["labels_cap.png"], np.uint16, 1, (h, w))
    amodal_rle = _json(folder / "amodal_caps.json", raw["amodal_caps.json"])
    try:
        amodal = {int(k): decode_mask(v) for k, v in amodal_rle.items()}
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise CorruptFileError(folder / "amodal_caps.json", f"bad RLE ({exc})") from exc
    anns = _json(folder / "annotations.json", raw["annotations.json"])
    return SceneSample(index, cv2.cvtColor(rgb, cv2.COLOR_BGR2RGB), depth.astype(np.float32) * DEPTH_SCALE,
                       lm, lc, amodal, record, anns.get("annotations", []))


def scene_indices(root: str | Path, split: str | None) -> list[int]:
    """Indices of a dataset's complete scenes (of ``split``, or all), in the manifest's order."""
    path = Path(root) / "manifest.json"
    manifest = _json(path, _read_bytes(path))
    try:
        return [e["index"] for e in manifest["scenes"] if split is None or e["split"] == split]
    except (KeyError, TypeError) as exc:
        raise CorruptFileError(path, f"bad scene list ({exc})") from exc


def dataset_checksum(root: str | Path, split: str | None = None) -> str:
    """A SHA-256 of a dataset's complete scenes (of ``split``, or all) as the generator recorded
    them: each one's index and ``DONE`` file, which holds the SHA-256 of each of its files. A
    dataset regenerated at the same path (another seed, other settings) gets another one, the
    same scenes the same one; it reads one small file per scene, not the images."""
    root = Path(root)
    digest = hashlib.sha256()
    for index in scene_indices(root, split):
        done = root / scene_dirname(index) / DONE
        digest.update(f"{index}\n".encode())
        digest.update(_read_bytes(done))
    return digest.hexdigest()


class SceneDataset(Dataset):
    """Whole scenes: ``rgb`` (3, H, W) float in [0, 1], ``depth`` (H, W) metres, ``labels_mushroom``
    / ``labels_cap`` (H, W) int64, ``K`` (3, 3), ``world_from_camera`` (4, 4), plus ``scene_id``,
    ``instances`` (scene.json's list) and ``annotations`` (COCO dicts). Use ``collate_fn=list``
    or ``collate_scenes`` to batch."""

    def __init__(self, root: str | Path, split: str | None = None, verify: bool = True) -> None:
        self.root = Path(root)
        self.verify = verify
        self.indices = scene_indices(self.root, split)

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, i: int) -> dict[str, Any]:
        s = read_scene_files(self.root / scene_dirname(self.indices[i]), self.verify)
        return {
            "scene_id": s.index,
            "rgb": torch.from_numpy(np.ascontiguousarray(s.rgb.transpose(2, 0, 1))).float() / 255.0,
            "depth": torch.from_numpy(s.depth),
            "labels_mushroom": torch.from_numpy(s.labels_mushroom.astype(np.int64)),
            "labels_cap": torch.from_numpy(s.labels_cap.astype(np.int64)),
            "K": torch.from_numpy(s.K),
            "world_from_camera": torch.from_numpy(s.world_from_camera),
            "instances": s.record["instances"],
            "annotations": s.annotations,
        }


def collate_scenes(batch: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return batch


def instance_in_camera(instance: dict[str, Any], world_from_camera: np.ndarray) -> dict[str, Any]:
    """An instance's ground truth in the OpenCV camera frame: ``R_cam = R_wc^T R_instance``."""
    r_wc, t_wc = world_from_camera[:3, :3], world_from_camera[:3, 3]
    rot = np.asarray(instance["rotation"], dtype=np.float64)
    to_cam = lambda p: r_wc.T @ (np.asarray(p, dtype=np.float64) - t_wc)  # noqa: E731
    return {
        "rotation": r_wc.T @ rot,
        "stem_axis": r_wc.T @ np.asarray(instance["stem_axis"], dtype=np.float64),
        "cap_top": to_cam(instance["cap_top"]),
        "cap_center": to_cam(instance["cap_obb"]["center"]),
        "stem_base": to_cam(instance["stem_base"]),
    }


class InstancePointCloudDataset(Dataset):
    """Per-instance point clouds in the camera frame (OpenCV), from depth + visible mask.

    Items: ``points`` (num_points, 3) float32 metres (sampled with a generator seeded by
    ``(seed, item)``: repeatable), ``rotation`` (3, 3) and ``stem_axis`` (3,) in the camera frame,
    ``cap_top`` / ``cap_center`` (3,), and ``meta`` (scene_id, instance_id, species,
    cap_diameter m, tilt_deg, num_valid points)."""

    def __init__(self, root: str | Path, split: str | None = None, num_points: int = 1024, cap_only: bool = False,
                 min_points: int = 32, seed: int = 0, verify: bool = True, cache_scenes: int = 4) -> None:
        self.root = Path(root)
        self.num_points, self.cap_only, self.seed, self.verify = num_points, cap_only, seed, verify
        category = 2 if cap_only else 1
        self.items: list[tuple[int, int]] = []
        for idx in scene_indices(self.root, split):
            path = self.root / scene_dirname(idx) / "annotations.json"
            anns = _json(path, _read_bytes(path)).get("annotations", [])
            self.items += [(idx, a["instance_id"]) for a in anns
                           if a["category_id"] == category and a["area"] >= min_points]
        self._load = lru_cache(maxsize=cache_scenes)(self._load_scene)

    def _load_scene(self, index: int) -> SceneSample:
        return read_scene_files(self.root / scene_dirname(index), self.verify)

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict[str, Any]:
        scene_id, iid = self.items[i]
        s = self._load(scene_id)
        intr = s.record["camera"]["intrinsics"]
        labels = s.labels_cap if self.cap_only else s.labels_mushroom
        points, _ = backproject(s.depth, intr["fx"], intr["fy"], intr["cx"], intr["cy"], labels == iid + 1)
        if len(points) == 0:
            raise CorruptFileError(self.root / scene_dirname(scene_id) / "depth.png",
                                   f"no valid depth under instance {iid}'s mask")
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, i]))
        n = len(points)
        idx = rng.choice(n, self.num_points, replace=False) if n >= self.num_points else \
            np.concatenate([rng.permutation(n), rng.integers(0, n, self.num_points - n)])
        inst = next(m for m in s.record["instances"] if m["id"] == iid)
        gt = instance_in_camera(inst, s.world_from_camera)
        return {
            "points": torch.from_numpy(points[idx].astype(np.float32)),
            "rotation": torch.from_numpy(gt["rotation"]).float(),
            "stem_axis": torch.from_numpy(gt["stem_axis"]).float(),
            "cap_top": torch.from_numpy(gt["cap_top"]).float(),
            "cap_center": torch.from_numpy(gt["cap_center"]).float(),
            "meta": {"scene_id": scene_id, "instance_id": iid, "species": inst["species"],
                     "cap_diameter": inst["cap_diameter"], "num_valid": n,
                     "tilt_deg": float(np.degrees(tilt_angle(np.asarray(inst["rotation"]))))},
        }


def load_scene(root: str | Path, index: int, verify: bool = True) -> Scene:
    """The ``Scene`` of scene ``index`` (``SceneFormatError`` reported as ``CorruptFileError``);
    ``verify``: ``CorruptFileError`` unless ``scene.json`` matches its ``DONE`` checksum."""
    folder = Path(root) / scene_dirname(index)
    path = folder / "scene.json"
    if verify:
        done = folder / DONE
        if not done.is_file():
            raise CorruptFileError(done, "missing: the scene was never completed")
        sums = _json(done, _read_bytes(done))
        if hashlib.sha256(_read_bytes(path)).hexdigest() != sums.get("scene.json"):
            raise CorruptFileError(path, "checksum differs from the one recorded in DONE")
    try:
        return Scene.load(path)
    except SceneFormatError as exc:
        raise CorruptFileError(path, str(exc)) from exc


def load_scenes(root: str | Path, split: str | None = None, verify: bool = True) -> list[Scene]:
    """Every complete scene of a dataset (or of one split), in index order; ``verify`` checks
    each ``scene.json`` against the checksum its ``DONE`` records (as ``SceneDataset`` does)."""
    root = Path(root)
    return [load_scene(root, i, verify) for i in scene_indices(root, split)]
