"""The axis CNN: a small 2-D convolutional network that reads a mushroom's stem axis from an
RGB-D crop around its mask (``depth_crops``), and its estimator.

Why a second stage-2 network: the point network reads a cloud of back-projected pixels, where a
stereo camera's noise (correlated over its matching window, 1.9 mm at 0.4 m for a D405) is a
jitter of every point. In the image the same noise is a texture that convolutions average away,
and the mask's outline and the cap's shading are there unjittered. Trained on the same scenes
and masks, it reads 3.74° / 5.80° mean stem-axis error (clean / camera model) on held-out beds
where the point network reads 8.5° / 15.4° (docs/results-perception.md).

It estimates the stem axis only. A mushroom is close to a solid of revolution, and the picker
uses nothing else; :func:`rotation_from_axis` completes it to a rotation with an arbitrary yaw.

Test-time augmentation: the eight quarter turns and mirror images of a crop are exact symmetries
of the task (the axis turns and mirrors with the image), so the estimate is the mean of the
eight views' axes turned back (``dihedral``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from perception.errors import CheckpointFormatError, NoEstimate, PerceptionConfigError
from perception.pose.depth_crops import CROP_CHANNELS, CROP_SIZE, crop_around_mask
from perception.run_files import atomic_torch_save, read_torch_file

#: The shipped weights (``sms3d train-axis-cnn``; recipe and metrics in the README beside them).
SHIPPED_AXIS_CNN = Path(__file__).resolve().parents[1] / "weights" / "axis_cnn" / "axis_cnn.pt"
#: Checkpoint format version.
FORMAT = 1


@dataclass(frozen=True)
class AxisCNNConfig:
    """The network's shape: ``width`` channels after the first block (doubled twice), a hidden
    layer of ``hidden`` units, on crops of ``crop_size`` pixels with ``channels`` channels."""

    width: int = 32
    hidden: int = 128
    crop_size: int = CROP_SIZE
    channels: int = CROP_CHANNELS

    def __post_init__(self) -> None:
        for name in ("width", "hidden"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise PerceptionConfigError(name, f"must be an int >= 1, got {value!r}")
        if (self.crop_size, self.channels) != (CROP_SIZE, CROP_CHANNELS):
            raise PerceptionConfigError("crop_size", f"crops are {CROP_CHANNELS} x {CROP_SIZE} x {CROP_SIZE}, "
                                                     f"got {self.channels} x {self.crop_size}")


def _block(c_in: int, c_out: int, stride: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False), nn.BatchNorm2d(c_out), nn.ReLU(inplace=True))


class AxisCNN(nn.Module):
    """``(B, channels, S, S)`` crops → ``(B, 3)`` unit stem axes in the crops' ray frames.

    Three stride-2 stages of two 3 x 3 conv blocks (``width``, 2 ``width``, 4 ``width``
    channels), global average pooling, a hidden layer, a unit vector. The output layer starts
    at zero weight with the bias of an upright mushroom seen from above (``(0, 0, -1)``: the
    axis points at the camera), so training starts from the upright prior."""

    def __init__(self, config: AxisCNNConfig | None = None) -> None:
        super().__init__()
        self.config = config or AxisCNNConfig()
        w = self.config.width
        self.features = nn.Sequential(
            _block(self.config.channels, w, 2), _block(w, w, 1), _block(w, 2 * w, 2), _block(2 * w, 2 * w, 1),
            _block(2 * w, 4 * w, 2), _block(4 * w, 4 * w, 1), nn.AdaptiveAvgPool2d(1), nn.Flatten())
        self.head = nn.Sequential(nn.Linear(4 * w, self.config.hidden), nn.ReLU(inplace=True),
                                  nn.Linear(self.config.hidden, 3))
        nn.init.zeros_(self.head[2].weight)
        with torch.no_grad():
            self.head[2].bias.copy_(torch.tensor([0.0, 0.0, -1.0]))

    def forward(self, crops: torch.Tensor) -> torch.Tensor:
        return nn.functional.normalize(self.head(self.features(crops)), dim=-1)


def dihedral(crops: torch.Tensor, axes: torch.Tensor, quarter_turns: int, mirror: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """Turn ``crops (B, C, S, S)`` by ``quarter_turns`` (``torch.rot90`` over the image axes),
    then mirror them left-right if ``mirror``; ``axes (B, 3)`` turn with them.

    A quarter turn takes a direction ``(x, y)`` in the image (x right, y down, as the camera's
    axes) to ``(y, -x)``; the mirror takes it to ``(-x, y)``; the depth component stays."""
    crops = torch.rot90(crops, quarter_turns, dims=(-2, -1))
    for _ in range(quarter_turns % 4):
        axes = torch.stack([axes[:, 1], -axes[:, 0], axes[:, 2]], 1)
    if mirror:
        crops = torch.flip(crops, dims=(-1,))
        axes = torch.stack([-axes[:, 0], axes[:, 1], axes[:, 2]], 1)
    return crops, axes


def undo_dihedral(axes: torch.Tensor, quarter_turns: int, mirror: bool) -> torch.Tensor:
    """The inverse of :func:`dihedral` on axes."""
    if mirror:
        axes = torch.stack([-axes[:, 0], axes[:, 1], axes[:, 2]], 1)
    for _ in range(quarter_turns % 4):
        axes = torch.stack([-axes[:, 1], axes[:, 0], axes[:, 2]], 1)
    return axes


def predict_axes(model: AxisCNN, crops: torch.Tensor, batch: int = 256) -> torch.Tensor:
    """Unit axes ``(B, 3)`` in the ray frames: the mean of the 8 dihedral views, turned back."""
    model.eval()
    out = []
    with torch.no_grad():
        for start in range(0, len(crops), batch):
            chunk = crops[start:start + batch].float()
            total = torch.zeros(len(chunk), 3)
            for turns in range(4):
                for mirror in (False, True):
                    view, _ = dihedral(chunk, torch.zeros(len(chunk), 3), turns, mirror)
                    total += undo_dihedral(model(view), turns, mirror)
            out.append(nn.functional.normalize(total, dim=-1))
    return torch.cat(out) if out else torch.zeros(0, 3)


def rotation_from_axis(axis: np.ndarray) -> np.ndarray:
    """A rotation ``(3, 3)`` whose third column is the unit ``axis``; its yaw about the axis is
    arbitrary (the x column is the axis-perpendicular part of the frame's x, or y)."""
    z = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = helper - (helper @ z) * z
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], 1)


def save_axis_cnn(path: str | Path, model: AxisCNN, extra: dict[str, Any] | None = None) -> None:
    """Write ``model`` (config, weights, ``extra``) atomically."""
    atomic_torch_save({"format": FORMAT, "config": dataclasses.asdict(model.config),
                       "state_dict": model.state_dict(), "extra": extra or {}}, path)


def load_axis_cnn(path: str | Path) -> tuple[AxisCNN, dict[str, Any]]:
    """The network stored at ``path`` (in eval mode) and its ``extra``.

    Raises:
        FileNotFoundError: no such file.
        CheckpointFormatError: not an axis-CNN checkpoint, or weights that do not fit its config.
    """
    payload = read_torch_file(path, "axis-CNN checkpoint")
    if not isinstance(payload, dict) or payload.get("format") != FORMAT or "state_dict" not in payload:
        raise CheckpointFormatError(f"{path}: not an axis-CNN checkpoint (format {FORMAT})")
    model = AxisCNN(AxisCNNConfig(**payload["config"]))
    try:
        model.load_state_dict(payload["state_dict"])
    except RuntimeError as exc:
        raise CheckpointFormatError(f"{path}: weights do not fit {model.config} ({exc})") from exc
    return model.eval(), payload.get("extra", {})


class AxisCNNEstimator:
    """Stem axes of masked mushrooms in one RGB-D frame, in the camera frame.

    >>> estimator = AxisCNNEstimator.from_pretrained()  # doctest: +SKIP
    >>> axes = estimator.estimate_axes(rgb, depth, [mask], intrinsics)  # doctest: +SKIP
    """

    def __init__(self, model: AxisCNN, path: str | Path | None = None) -> None:
        self.model = model.eval()
        self.path = None if path is None else Path(path)

    @classmethod
    def from_checkpoint(cls, path: str | Path) -> AxisCNNEstimator:
        return cls(load_axis_cnn(path)[0], path)

    @classmethod
    def from_pretrained(cls) -> AxisCNNEstimator:
        """The shipped network (``perception/weights/axis_cnn/axis_cnn.pt``)."""
        return cls.from_checkpoint(SHIPPED_AXIS_CNN)

    def estimate_axes(self, rgb: np.ndarray, depth: np.ndarray, masks: list[np.ndarray],
                      intrinsics: Any) -> list[np.ndarray | None]:
        """One unit stem axis ``(3,)`` (camera frame, pointing from the stem to the cap) per
        boolean mask, or ``None`` for a mask with too few valid depth pixels. ``intrinsics``:
        anything :func:`~perception.pointcloud.pinhole_intrinsics` takes (an ``Intrinsics``, a
        3x3 camera matrix)."""
        from perception.errors import PipelineInputError
        from perception.pointcloud import pinhole_intrinsics

        k = pinhole_intrinsics(intrinsics)
        rgb, depth = np.asarray(rgb), np.asarray(depth)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise PipelineInputError(f"rgb: expected (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
        if depth.shape != rgb.shape[:2] or not np.issubdtype(depth.dtype, np.floating):
            raise PipelineInputError(f"depth: expected float metres of shape {rgb.shape[:2]}, got {depth.shape} {depth.dtype}")
        bad = [i for i, m in enumerate(masks) if np.shape(m) != depth.shape]
        if bad:
            raise PipelineInputError(f"masks {bad}: expected shape {depth.shape}")
        crops, rays, index = [], [], []
        for i, mask in enumerate(masks):
            try:
                c = crop_around_mask(rgb, depth, np.asarray(mask, bool), k.fx, k.fy, k.cx, k.cy)
            except NoEstimate:
                continue
            crops.append(c.image)
            rays.append(c.ray_from_camera)
            index.append(i)
        out: list[np.ndarray | None] = [None] * len(masks)
        if crops:
            axes = predict_axes(self.model, torch.from_numpy(np.stack(crops))).numpy().astype(np.float64)
            for i, ray_from_camera, axis in zip(index, rays, axes):
                out[i] = ray_from_camera.T @ axis
        return out
