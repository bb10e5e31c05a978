"""A generated dataset's COCO split as Mask R-CNN training data: ``(image, target)`` pairs.

Targets follow torchvision's detection convention: ``boxes`` (N, 4) float ``x0, y0, x1, y1``
(exclusive right/bottom edges), ``labels`` (N,) int64 (1 = the detected category), ``masks``
(N, H, W) uint8. Masks come from the COCO RLEs that ``sms3d generate`` wrote, so training and
``eval-detector`` read exactly what pycocotools reads.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np
import torch
from torch.utils.data import Dataset

from generator.dataset.coco import decode_mask
from generator.dataset.errors import CorruptFileError
from generator.dataset.writer import DEPTH_SCALE
from perception.choices import CATEGORIES
from perception.errors import PerceptionConfigError

T = TypeVar("T")


def coco_path(root: str | Path, split: str) -> Path:
    """The COCO file of ``split`` in a dataset folder (``FileNotFoundError`` naming it if absent)."""
    path = Path(root) / f"coco_{split}.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no COCO file for split {split!r} (is {root} a finished `sms3d generate` folder?)")
    return path


def first_n(items: list[T], limit: int | None, name: str) -> list[T]:
    """The first ``limit`` of a split's ``items`` (all of them for ``None``). A limit below 1 is a
    :class:`PerceptionConfigError` naming ``name``: a slice would take none (0) or quietly drop
    the last item (-1)."""
    if limit is None:
        return items
    if isinstance(limit, bool) or not isinstance(limit, int) or limit < 1:
        raise PerceptionConfigError(name, f"must be an integer >= 1 or None (all), got {limit!r}")
    return items[:limit]


def load_coco(root: str | Path, split: str) -> dict[str, Any]:
    path = coco_path(root, split)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        data["images"], data["annotations"]  # noqa: B018 - both keys must exist
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as exc:
        raise CorruptFileError(path, f"not a COCO instance file ({exc})") from exc
    return data


class CocoDetectionDataset(Dataset):
    """Images and instance targets of one category (``mushroom`` or ``mushroom_cap``) of a split.

    Masks smaller than ``min_area`` pixels are left out (slivers of occluded mushrooms that no
    detector can be asked to find). ``augment`` flips images horizontally and vertically at
    random (the camera looks straight down, so both flips give valid beds), drawn from
    ``torch``'s global generator so that seeded training is reproducible.
    """

    def __init__(self, root: str | Path, split: str, category: str = "mushroom", min_area: int = 16,
                 augment: bool = False) -> None:
        if category not in CATEGORIES:
            raise ValueError(f"category: {category!r} is not one of {tuple(CATEGORIES)}")
        self.root = Path(root)
        self.coco = load_coco(root, split)
        self.images = sorted(self.coco["images"], key=lambda im: im["id"])
        self.category_id = CATEGORIES[category]
        self.min_area = min_area
        self.augment = augment
        self._anns: dict[int, list[dict[str, Any]]] = {im["id"]: [] for im in self.images}
        for ann in self.coco["annotations"]:
            if ann["category_id"] == self.category_id and ann["area"] >= min_area and ann["image_id"] in self._anns:
                self._anns[ann["image_id"]].append(ann)

    def __len__(self) -> int:
        return len(self.images)

    def image_rgb(self, i: int) -> np.ndarray:
        path = self.root / self.images[i]["file_name"]
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise CorruptFileError(path, "unreadable image")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)

    def image_depth(self, i: int) -> np.ndarray:
        """The image's depth in metres (0 = invalid), from the scene folder's ``depth.png``."""
        path = self.root / self.images[i]["depth_file"]
        depth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if depth is None or depth.dtype != np.uint16:
            raise CorruptFileError(path, "unreadable 16-bit depth image")
        return depth.astype(np.float32) * DEPTH_SCALE

    def target(self, i: int) -> dict[str, torch.Tensor]:
        image = self.images[i]
        anns = self._anns[image["id"]]
        h, w = image["height"], image["width"]
        masks = np.zeros((len(anns), h, w), np.uint8)
        boxes = np.zeros((len(anns), 4), np.float32)
        for k, ann in enumerate(anns):
            masks[k] = decode_mask(ann["segmentation"])
            x, y, bw, bh = ann["bbox"]
            boxes[k] = (x, y, x + bw, y + bh)
        return {"boxes": torch.from_numpy(boxes), "labels": torch.ones(len(anns), dtype=torch.int64),
                "masks": torch.from_numpy(masks), "image_id": torch.tensor(image["id"])}

    def __getitem__(self, i: int) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        rgb = torch.from_numpy(np.ascontiguousarray(self.image_rgb(i).transpose(2, 0, 1))).float().div_(255.0)
        target = self.target(i)
        if self.augment:
            h, w = rgb.shape[1:]
            if torch.rand(()) < 0.5:
                rgb, target["masks"] = rgb.flip(-1), target["masks"].flip(-1)
                target["boxes"] = target["boxes"][:, [2, 1, 0, 3]] * torch.tensor([-1, 1, -1, 1]) + torch.tensor([w, 0, w, 0])
            if torch.rand(()) < 0.5:
                rgb, target["masks"] = rgb.flip(-2), target["masks"].flip(-2)
                target["boxes"] = target["boxes"][:, [0, 3, 2, 1]] * torch.tensor([1, -1, 1, -1]) + torch.tensor([0, h, 0, h])
        return rgb, target


def collate_detection(batch: list[tuple[torch.Tensor, dict[str, torch.Tensor]]]) -> tuple[list, list]:
    images, targets = zip(*batch)
    return list(images), list(targets)
