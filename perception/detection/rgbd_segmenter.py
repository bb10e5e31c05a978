"""An RGB-D instance segmenter for stage 1: a small U-Net with a mask, a centre and an offset head.

Mask R-CNN (``perception.baselines.maskrcnn.model``) sees RGB only and paints 28 × 28 masks that spill
over a mushroom's silhouette onto the soil; trained from scratch on this project's CPU it reached
mask F1 0.74. This project renders metric depth for every pixel, and a mushroom is a bump on the
soil, so a bottom-up segmenter on colour *and* depth is a better fit (the design is
Panoptic-DeepLab's, Cheng et al., CVPR 2020: semantic mask + instance-centre heatmap + per-pixel
offset to the centre, grouped by nearest centre):

- input: RGB and the depth's height above the image's median depth (in units of
  ``DEPTH_SCALE_M``), with a validity channel (0 where the sensor gave no depth), at half the
  image's resolution;
- heads (half resolution): mushroom logit, centre-heatmap logit, offset to the instance's
  centre (half-resolution pixels / ``OFFSET_SCALE``);
- decoding (``instances_from_heads``): centre peaks above ``centre_threshold`` after a
  ``peak_window`` max-pool, mushroom pixels (probability > ``mask_threshold``, upsampled to the
  full image) assigned to the peak nearest to where their offset points; a detection's score is
  its peak's heat.

Shapes: images (H, W, 3) uint8 and depth (H, W) float metres (0 = invalid); H and W need not be
multiples of anything (the half-resolution input is padded to a multiple of ``PAD_MULTIPLE``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from perception.detection.detector import Detection
from perception.detection.segmenter_config import SegmenterConfig
from perception.errors import CheckpointFormatError, PerceptionConfigError, PipelineInputError
from perception.run_files import atomic_torch_save, read_torch_file

CHECKPOINT_FORMAT = "sms3d-rgbd-segmenter-1"
#: Height above the median depth is fed in units of this many metres (mushrooms stand 2–10 cm).
DEPTH_SCALE_M = 0.05
#: Offsets are predicted in half-resolution pixels divided by this (keeps targets near unit size).
OFFSET_SCALE = 16.0
#: The network's half-resolution input is padded to a multiple of this (its four 2× poolings).
PAD_MULTIPLE = 16


def _block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
                         nn.Conv2d(cout, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class RGBDUNet(nn.Module):
    """``(B, 5, h, w)`` input (RGB, height, validity; h and w multiples of 16) to
    ``(B, 4, h, w)``: mushroom logit, centre logit, offset (du, dv)."""

    IN_CHANNELS = 5

    def __init__(self, widths: tuple[int, ...]) -> None:
        super().__init__()
        self.down = nn.ModuleList()
        cin = self.IN_CHANNELS
        for w in widths:
            self.down.append(_block(cin, w))
            cin = w
        self.up = nn.ModuleList()
        self.merge = nn.ModuleList()
        for w_skip in reversed(widths[:-1]):
            self.up.append(nn.Conv2d(cin, w_skip, 1))
            self.merge.append(_block(2 * w_skip, w_skip))
            cin = w_skip
        self.mask_head = nn.Conv2d(cin, 1, 1)
        self.centre_head = nn.Conv2d(cin, 1, 1)
        self.offset_head = nn.Conv2d(cin, 2, 1)
        # Centre heat starts near 0 everywhere (CenterNet's prior), not at 0.5.
        nn.init.constant_(self.centre_head.bias, -4.0)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for i, block in enumerate(self.down):
            x = block(x if i == 0 else F.max_pool2d(x, 2))
            skips.append(x)
        for up, merge, skip in zip(self.up, self.merge, reversed(skips[:-1])):
            x = F.interpolate(up(x), size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = merge(torch.cat([x, skip], 1))
        return torch.cat([self.mask_head(x), self.centre_head(x), self.offset_head(x)], 1)


def check_rgbd(rgb: np.ndarray, depth: np.ndarray | None) -> None:
    """``PipelineInputError`` for images the segmenter cannot read."""
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise PipelineInputError(f"rgb: expected (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
    if depth is None:
        raise PipelineInputError("depth: the RGB-D segmenter needs the depth image (H, W) in metres")
    depth = np.asarray(depth)
    if depth.shape != rgb.shape[:2] or not np.issubdtype(depth.dtype, np.floating):
        raise PipelineInputError(f"depth: expected ({rgb.shape[0]}, {rgb.shape[1]}) float metres, got {depth.shape} {depth.dtype}")


def network_input(rgb: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """The network's ``(5, H/2, W/2)`` float32 input of one RGB-D image (see the module doc)."""
    h, w = rgb.shape[0] // 2, rgb.shape[1] // 2
    small_rgb = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0 - 0.5
    small_depth = cv2.resize(np.nan_to_num(depth.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0), (w, h),
                             interpolation=cv2.INTER_NEAREST)
    valid = small_depth > 0
    reference = float(np.median(small_depth[valid])) if valid.any() else 0.0
    height = np.where(valid, (reference - small_depth) / DEPTH_SCALE_M, 0.0).astype(np.float32)
    return np.concatenate([small_rgb.transpose(2, 0, 1), height[None], valid[None].astype(np.float32)], 0)


def pad_to_multiple(x: torch.Tensor, multiple: int = PAD_MULTIPLE) -> torch.Tensor:
    """Zero-pad the last two dimensions of ``x`` up to multiples of ``multiple``."""
    h, w = x.shape[-2:]
    return F.pad(x, (0, (-w) % multiple, 0, (-h) % multiple))


def instances_from_heads(heads: torch.Tensor, image_shape: tuple[int, int], config: SegmenterConfig) -> list[Detection]:
    """Detections from one image's ``heads (4, h, w)`` (half resolution, cropped to the image):
    centre peaks, then every mushroom pixel of the full ``image_shape`` joined to the peak
    nearest to where its offset points."""
    full_h, full_w = image_shape
    heat = torch.sigmoid(heads[1])
    pooled = F.max_pool2d(heat[None, None], config.peak_window, stride=1, padding=config.peak_window // 2)[0, 0]
    peaks = torch.nonzero((heat == pooled) & (heat > config.centre_threshold))
    if len(peaks) == 0:
        return []
    scores = heat[peaks[:, 0], peaks[:, 1]]
    # Upsample mask logits and offsets to the full image (offsets: half-res px -> full-res px).
    full = F.interpolate(heads[None, [0, 2, 3]], size=(full_h, full_w), mode="bilinear", align_corners=False)[0]
    mask = torch.sigmoid(full[0]) > config.mask_threshold
    vs, us = torch.nonzero(mask, as_tuple=True)
    if len(vs) == 0:
        return []
    # Centres of half-res pixel (r, c) lie at full-res (2c + 0.5, 2r + 0.5).
    centres = torch.stack([peaks[:, 1] * 2.0 + 0.5, peaks[:, 0] * 2.0 + 0.5], 1)
    pointed = torch.stack([us + full[1, vs, us] * OFFSET_SCALE * 2.0, vs + full[2, vs, us] * OFFSET_SCALE * 2.0], 1)
    owner = torch.cdist(pointed, centres).argmin(1)
    labels = np.zeros((full_h, full_w), np.int64)
    labels[vs.numpy(), us.numpy()] = owner.numpy() + 1
    detections = []
    for k in range(len(peaks)):
        inst = labels == k + 1
        area = int(inst.sum())
        if area < config.min_area:
            continue
        rows, cols = np.nonzero(inst)
        box = (int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max()))
        detections.append(Detection(inst, box, float(scores[k])))
    detections.sort(key=lambda d: -d.score)
    return detections


class RGBDSegmenter:
    """The ``Detector`` of this module: ``detect(rgb, depth) -> [Detection]``, best score first."""

    def __init__(self, model: RGBDUNet, config: SegmenterConfig, threads: int | None = None) -> None:
        self.model = model.eval()
        self.config = config
        self.threads = threads
        self.score_threshold = config.score_threshold

    @torch.no_grad()
    def detect(self, rgb: np.ndarray, depth: np.ndarray | None = None) -> list[Detection]:
        check_rgbd(rgb, depth)
        if self.threads is not None:
            torch.set_num_threads(self.threads)
        x = torch.from_numpy(network_input(rgb, depth))
        h, w = x.shape[-2:]
        heads = self.model(pad_to_multiple(x[None]))[0, :, :h, :w]
        return instances_from_heads(heads, rgb.shape[:2], self.config)


def build_segmenter(config: SegmenterConfig | None = None) -> RGBDUNet:
    return RGBDUNet((config or SegmenterConfig()).widths)


def save_segmenter(path: str | Path, model: RGBDUNet, config: SegmenterConfig, extra: dict[str, Any] | None = None) -> None:
    """Write a checkpoint atomically (a killed write never leaves a half file at ``path``)."""
    atomic_torch_save({"format": CHECKPOINT_FORMAT, "config": config.to_dict(), "model": model.state_dict(),
                       **(extra or {})}, path)


def read_segmenter_checkpoint(path: str | Path) -> dict[str, Any]:
    """The raw checkpoint dict (tensors and plain values only), or ``CheckpointFormatError``
    naming the file if it is not a segmenter's."""
    state = read_torch_file(path, "segmenter checkpoint")
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointFormatError(f"{path}: not an RGB-D segmenter checkpoint (format {CHECKPOINT_FORMAT!r})")
    return state


def load_segmenter(path: str | Path, threads: int | None = None, **overrides: Any) -> RGBDSegmenter:
    """The segmenter stored at ``path``; ``overrides`` change decoding settings (thresholds)."""
    state = read_segmenter_checkpoint(path)
    stored = dict(state["config"])
    unknown = set(overrides) - set(stored)
    if unknown:
        raise PerceptionConfigError(sorted(unknown)[0], f"not a SegmenterConfig field (fields: {sorted(stored)})")
    config = SegmenterConfig(**{**stored, **overrides})
    if config.widths != tuple(stored["widths"]):
        raise PerceptionConfigError("widths", "the network's widths are fixed by the checkpoint")
    model = build_segmenter(config)
    try:
        model.load_state_dict(state["model"])
    except RuntimeError as exc:
        raise CheckpointFormatError(f"{path}: weights do not fit widths {config.widths} ({exc})") from exc
    return RGBDSegmenter(model, config, threads)


def centre_heatmap(centres: np.ndarray, shape: tuple[int, int], sigma: float) -> np.ndarray:
    """``(h, w)`` float32 heatmap: the maximum over ``centres (K, 2)`` (u, v in pixels, rounded
    to the nearest pixel, so that each centre has one pixel of heat exactly 1, the positive of
    the focal loss) of Gaussians of ``sigma`` pixels."""
    h, w = shape
    heat = np.zeros((h, w), np.float32)
    radius = int(math.ceil(3 * sigma))
    for u, v in centres:
        u0, v0 = int(round(u)), int(round(v))
        a, b = max(u0 - radius, 0), min(u0 + radius + 1, w)
        c, d = max(v0 - radius, 0), min(v0 + radius + 1, h)
        if a >= b or c >= d:
            continue
        gu = np.exp(-((np.arange(a, b) - u0) ** 2) / (2 * sigma**2))
        gv = np.exp(-((np.arange(c, d) - v0) ** 2) / (2 * sigma**2))
        np.maximum(heat[c:d, a:b], np.outer(gv, gu).astype(np.float32), out=heat[c:d, a:b])
    return heat
