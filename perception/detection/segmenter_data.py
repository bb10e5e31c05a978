"""Generated scenes as training data for the RGB-D segmenter: inputs and head targets.

Each scene of a ``sms3d generate`` folder becomes, at half resolution (``h, w = H // 2, W // 2``):

- ``inputs (5, h, w)`` float32: ``rgbd_segmenter.network_input``;
- ``mushroom (h, w)`` float32: 1 on visible mushroom pixels (``labels_mushroom.png``);
- ``mask_weight (h, w)`` float32: 0 on slivers (instances under ``min_area`` full-resolution
  pixels, which no detector is asked to find and whose pixels would join a neighbour), else 1;
- ``centre (h, w)`` float32: Gaussian heat at each instance's visible centroid;
- ``offset (2, h, w)`` float32: (centroid - pixel) / ``OFFSET_SCALE`` on the instance's pixels;
- ``offset_weight (h, w)`` float32: 1 where an offset is defined.

Training draws a random square crop of each scene, flipped and transposed at random (the
camera looks straight down: every flip of a bed is a valid bed). Scenes are decoded once and
kept in memory (about 2.6 MB per 640 × 480 scene).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from generator.dataset.readers import read_scene_files, scene_indices
from generator.dataset.writer import scene_dirname
from perception.detection.rgbd_segmenter import OFFSET_SCALE, centre_heatmap, network_input
from perception.errors import PerceptionConfigError


@dataclass(frozen=True)
class SegmenterSample:
    inputs: np.ndarray
    mushroom: np.ndarray
    mask_weight: np.ndarray
    centre: np.ndarray
    offset: np.ndarray
    offset_weight: np.ndarray

    def arrays(self) -> tuple[np.ndarray, ...]:
        return self.inputs, self.mushroom, self.mask_weight, self.centre, self.offset, self.offset_weight


def segmenter_targets(rgb: np.ndarray, depth: np.ndarray, labels: np.ndarray, sigma: float,
                      min_area: int = 16) -> SegmenterSample:
    """Inputs and targets of one scene (``labels``: visible instance ids + 1, 0 background)."""
    inputs = network_input(rgb, depth)
    h, w = inputs.shape[1:]
    full_counts = np.bincount(labels.ravel(), minlength=int(labels.max()) + 1)
    small = labels[: 2 * h: 2, : 2 * w: 2].astype(np.int64)
    mushroom = (small > 0).astype(np.float32)
    mask_weight = np.ones((h, w), np.float32)
    offset = np.zeros((2, h, w), np.float32)
    offset_weight = np.zeros((h, w), np.float32)
    centres = []
    vs, us = np.nonzero(small)
    ids = small[vs, us]
    for value in np.unique(ids):
        sel = ids == value
        if full_counts[value] < min_area:
            mask_weight[vs[sel], us[sel]] = 0.0
            continue
        cu, cv = us[sel].mean(), vs[sel].mean()
        centres.append((cu, cv))
        offset[0, vs[sel], us[sel]] = (cu - us[sel]) / OFFSET_SCALE
        offset[1, vs[sel], us[sel]] = (cv - vs[sel]) / OFFSET_SCALE
        offset_weight[vs[sel], us[sel]] = 1.0
    centre = centre_heatmap(np.array(centres).reshape(-1, 2), (h, w), sigma)
    return SegmenterSample(inputs, mushroom, mask_weight, centre, offset, offset_weight)


def scene_folders(roots: list[str | Path], split: str) -> list[Path]:
    """The scene folders of ``split`` in each dataset folder of ``roots``, in order."""
    folders = []
    for root in roots:
        root = Path(root)
        if not (root / "manifest.json").is_file():
            raise FileNotFoundError(f"{root}: no manifest.json (is it a finished `sms3d generate` folder?)")
        folders += [root / scene_dirname(i) for i in scene_indices(root, split)]
    return folders


class SegmenterDataset(Dataset):
    """Random crops of ``crop`` × ``crop`` half-resolution pixels of the scenes in ``folders``;
    item ``i`` is scene ``i`` with a fresh crop and flip (drawn from torch's global generator,
    so seeded training is reproducible)."""

    def __init__(self, folders: list[Path], crop: int = 160, sigma: float = 2.5, augment: bool = True) -> None:
        if not folders:
            raise PerceptionConfigError("data", "no training scenes")
        self.crop = crop
        self.augment = augment
        self.samples: list[SegmenterSample] = []
        for folder in folders:
            s = read_scene_files(folder, verify=False)
            self.samples.append(segmenter_targets(s.rgb, s.depth, s.labels_mushroom, sigma))
        h, w = self.samples[0].mushroom.shape
        if crop > min(h, w):
            raise PerceptionConfigError("crop", f"{crop} px is larger than the half-resolution image ({w} x {h})")

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, i: int) -> tuple[torch.Tensor, ...]:
        arrays = [torch.from_numpy(a) for a in self.samples[i].arrays()]
        h, w = arrays[1].shape
        top = int(torch.randint(0, h - self.crop + 1, ()))
        left = int(torch.randint(0, w - self.crop + 1, ()))
        arrays = [a[..., top:top + self.crop, left:left + self.crop] for a in arrays]
        inputs, mushroom, mask_weight, centre, offset, offset_weight = arrays
        if self.augment:
            if torch.rand(()) < 0.5:  # mirror left-right: u offsets change sign
                inputs, mushroom, mask_weight, centre, offset, offset_weight = (
                    a.flip(-1) for a in (inputs, mushroom, mask_weight, centre, offset, offset_weight))
                offset = offset * torch.tensor([-1.0, 1.0])[:, None, None]
            if torch.rand(()) < 0.5:  # mirror top-bottom: v offsets change sign
                inputs, mushroom, mask_weight, centre, offset, offset_weight = (
                    a.flip(-2) for a in (inputs, mushroom, mask_weight, centre, offset, offset_weight))
                offset = offset * torch.tensor([1.0, -1.0])[:, None, None]
            if torch.rand(()) < 0.5:  # transpose: u and v swap
                inputs, mushroom, mask_weight, centre, offset, offset_weight = (
                    a.transpose(-1, -2) for a in (inputs, mushroom, mask_weight, centre, offset, offset_weight))
                offset = offset.flip(0)
            gain = 1.0 + 0.2 * (torch.rand(()) - 0.5)  # brightness: the RGB channels only
            inputs = torch.cat([(inputs[:3] + 0.5) * gain - 0.5, inputs[3:]], 0)
        return tuple(a.contiguous() for a in (inputs, mushroom, mask_weight, centre, offset, offset_weight))
