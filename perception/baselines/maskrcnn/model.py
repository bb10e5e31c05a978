"""Mask R-CNN detectors (torchvision) for stage 1: instance masks of mushrooms on RGB.

Two configurations behind one ``DetectorConfig``:

- ``resnet50_fpn_v2``: torchvision's ``maskrcnn_resnet50_fpn_v2``, the SMS3D authors' choice;
- ``mobilenet_v3_fpn``: a MobileNetV3-Large FPN backbone under the same Mask R-CNN heads, light
  enough for a CPU.

Nothing is downloaded: networks start from random weights unless ``pretrained=True``, which uses
torchvision's weights only when they are already in torch's hub cache (``torch.hub.get_dir()``)
and otherwise raises ``PretrainedWeightsMissing`` naming the file to put there.
"""

from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from perception.baselines.maskrcnn.config import DetectorConfig
from perception.detection.detector import Detection
from perception.errors import CheckpointFormatError, CheckpointMismatchError
from perception.run_files import atomic_torch_save, read_torch_file

CHECKPOINT_FORMAT = "sms3d-maskrcnn-1"


class PretrainedWeightsMissing(FileNotFoundError):
    """``pretrained=True`` but torchvision's weight file is not in the local hub cache."""


def _import_torchvision():
    try:
        import torchvision  # noqa: F401
        from torchvision.models import detection
    except (ImportError, RuntimeError) as exc:  # RuntimeError: a torchvision built for another torch
        raise ImportError(
            "Mask R-CNN (a baseline) needs a working torchvision matching the installed torch "
            f"({exc}): install the baselines extra, `pip install -e \".[baselines]\"`, or both from "
            "the same release, e.g. `pip install torch torchvision`"
        ) from exc
    return detection


def _cached_weights(weights: Any) -> None:
    path = Path(torch.hub.get_dir()) / "checkpoints" / os.path.basename(weights.url)
    if not path.is_file():
        raise PretrainedWeightsMissing(
            f"pretrained weights {weights} are not cached (expected {path}); nothing is downloaded "
            "here: copy the file there or train from scratch without --pretrained")


def build_maskrcnn(config: DetectorConfig, pretrained: bool = False) -> nn.Module:
    """A torchvision ``MaskRCNN`` with two classes (background, ``config.category``)."""
    detection = _import_torchvision()
    from torchvision.models.detection.faster_rcnn import FastRCNNPredictor
    from torchvision.models.detection.mask_rcnn import MaskRCNNPredictor

    # A bed holds tens of mushrooms, not hundreds of objects: fewer proposals and sampled RoIs
    # than torchvision's COCO defaults cut CPU time without limiting recall.
    sizes = {"min_size": config.min_size, "max_size": config.max_size, "rpn_pre_nms_top_n_train": 1000,
             "rpn_post_nms_top_n_train": 1000, "rpn_pre_nms_top_n_test": 500, "rpn_post_nms_top_n_test": 300,
             "box_batch_size_per_image": 128}
    if config.arch == "resnet50_fpn_v2":
        if pretrained:
            weights = detection.MaskRCNN_ResNet50_FPN_V2_Weights.COCO_V1
            _cached_weights(weights)
            model = detection.maskrcnn_resnet50_fpn_v2(weights=weights, **sizes)
            # Keep the COCO-trained trunk and heads, replace only the class-specific predictors.
            model.roi_heads.box_predictor = FastRCNNPredictor(model.roi_heads.box_predictor.cls_score.in_features, 2)
            model.roi_heads.mask_predictor = MaskRCNNPredictor(256, 256, 2)
            return model
        return detection.maskrcnn_resnet50_fpn_v2(weights=None, weights_backbone=None, num_classes=2, **sizes)

    from torchvision.models import MobileNet_V3_Large_Weights
    from torchvision.models.detection.anchor_utils import AnchorGenerator
    from torchvision.models.detection.backbone_utils import mobilenet_backbone
    from torchvision.ops import MultiScaleRoIAlign

    backbone_weights = None
    if pretrained:
        backbone_weights = MobileNet_V3_Large_Weights.IMAGENET1K_V1
        _cached_weights(backbone_weights)
    # From scratch, batch norm must learn its statistics (torchvision freezes it for pretrained
    # backbones); its batches are whole images, so even 2 images give stable statistics.
    norm = None if pretrained else nn.BatchNorm2d
    backbone = mobilenet_backbone(backbone_name="mobilenet_v3_large", weights=backbone_weights, fpn=True,
                                  trainable_layers=6, **({"norm_layer": norm} if norm else {}))
    # Caps are 20-110 px across at the default camera: anchors start at 16 px.
    anchors = AnchorGenerator(((16, 32, 64, 128, 256),) * 3, ((0.5, 1.0, 2.0),) * 3)
    return detection.MaskRCNN(
        backbone, num_classes=2, rpn_anchor_generator=anchors,
        box_roi_pool=MultiScaleRoIAlign(["0", "1"], output_size=7, sampling_ratio=2),
        mask_roi_pool=MultiScaleRoIAlign(["0", "1"], output_size=14, sampling_ratio=2),
        **sizes,
    )


def image_tensor(rgb: np.ndarray) -> torch.Tensor:
    """(H, W, 3) uint8 RGB -> (3, H, W) float in [0, 1], the input torchvision detectors take."""
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"rgb: expected an (H, W, 3) uint8 image, got {rgb.shape} {rgb.dtype}")
    return torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1))).float().div_(255.0)


def detections_from_output(output: dict[str, torch.Tensor], config: DetectorConfig) -> list[Detection]:
    """torchvision's per-image output -> ``Detection`` list (score-thresholded, non-empty masks)."""
    keep = output["scores"] >= config.score_threshold
    masks = (output["masks"][keep, 0] >= config.mask_threshold).cpu().numpy()
    boxes = output["boxes"][keep].cpu().numpy()
    scores = output["scores"][keep].cpu().numpy()
    detections = []
    for mask, box, score in zip(masks, boxes, scores):
        if not mask.any():
            continue
        # torchvision's boxes are continuous (right/bottom edges exclusive); Detection's are pixels.
        x0, y0 = np.floor(box[:2]).astype(int)
        x1, y1 = np.ceil(box[2:]).astype(int) - 1
        detections.append(Detection(mask, (int(x0), int(y0), int(max(x1, x0)), int(max(y1, y0))), float(score)))
    return detections


class MaskRCNNDetector:
    """A trained Mask R-CNN behind the ``Detector`` protocol (RGB only: ``depth`` is ignored)."""

    def __init__(self, model: nn.Module, config: DetectorConfig, device: str | torch.device = "cpu") -> None:
        self.config = config
        self.device = torch.device(device)
        self.model = model.to(self.device).eval()

    @torch.no_grad()
    def detect(self, rgb: np.ndarray, depth: np.ndarray | None = None) -> list[Detection]:
        return self.detect_batch([rgb])[0]

    @torch.no_grad()
    def detect_batch(self, images: list[np.ndarray]) -> list[list[Detection]]:
        outputs = self.model([image_tensor(rgb).to(self.device) for rgb in images])
        return [detections_from_output(out, self.config) for out in outputs]

    @classmethod
    def from_checkpoint(cls, path: str | Path, device: str | torch.device = "cpu",
                        **overrides: Any) -> MaskRCNNDetector:
        """Load a checkpoint written by ``save_detector``; ``overrides`` change thresholds/sizes."""
        config, state = load_detector(path, **overrides)
        model = build_maskrcnn(config)
        try:
            model.load_state_dict(state)
        except RuntimeError as exc:
            raise CheckpointFormatError(f"{path}: weights do not fit a {config.arch} detector ({exc})") from exc
        return cls(model, config, device)


def save_detector(path: str | Path, model: nn.Module, config: DetectorConfig, extra: dict[str, Any] | None = None) -> Path:
    """Write weights + config atomically (a crash leaves the previous file intact)."""
    atomic_torch_save({"format": CHECKPOINT_FORMAT, "config": asdict(config), "model": model.state_dict(),
                       **(extra or {})}, path)
    return Path(path)


def read_detector_checkpoint(path: str | Path) -> dict[str, Any]:
    """The raw checkpoint dict (tensors and plain values only), or ``CheckpointFormatError`` if
    it is not one of ours."""
    data = read_torch_file(path, "detector checkpoint")
    if not isinstance(data, dict) or data.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointFormatError(f"{path}: not a Mask R-CNN detector checkpoint (format "
                                    f"{data.get('format') if isinstance(data, dict) else type(data).__name__!r})")
    return data


def load_detector(path: str | Path, **overrides: Any) -> tuple[DetectorConfig, dict[str, torch.Tensor]]:
    """Config and weights of a checkpoint. ``overrides`` may change thresholds and sizes; asking
    for another ``arch`` or ``category`` raises ``CheckpointMismatchError`` naming both."""
    data = read_detector_checkpoint(path)
    stored = DetectorConfig(**data["config"])
    config = DetectorConfig(**{**data["config"], **overrides})
    mismatches = {k: (v, config.architecture()[k]) for k, v in stored.architecture().items() if v != config.architecture()[k]}
    if mismatches:
        raise CheckpointMismatchError(str(path), mismatches)
    return config, data["model"]
