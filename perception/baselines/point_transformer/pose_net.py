"""PoseNet: a point-cloud backbone and a rotation head that outputs rotation matrices.

The input is a normalised per-mushroom cloud ``(B, N, 3)`` in the camera frame (``(B, N, 6)``
with RGB in [0, 1] when ``use_rgb``); the output is ``(B, 3, 3)`` camera-from-mushroom rotations
whose third column is the stem axis. Heads: ``"6d"`` (Gram–Schmidt), ``"6d_stem"`` (Gram–Schmidt
with the stem axis as the first, directly normalised vector), ``"9d"`` (SVD),
``"quat"`` (unit quaternion), ``"euler"`` (xyz angles). Checkpoints store the config, so a
network is always rebuilt with the shape it was trained with.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import torch
from torch import nn

from perception.baselines.point_transformer.backbones import build_backbone
from perception.baselines.point_transformer.config import PoseNetConfig
from perception.errors import CheckpointFormatError, CheckpointMismatchError
from perception.pose import rotations as rot
from perception.run_files import atomic_torch_save, read_torch_file

CHECKPOINT_FORMAT = "sms3d-posenet"
CHECKPOINT_VERSION = 1


class PoseNet(nn.Module):
    """Backbone → MLP head → rotation representation → ``(B, 3, 3)`` rotation matrix."""

    def __init__(self, config: PoseNetConfig | None = None, **kwargs: Any) -> None:
        super().__init__()
        if config is None:
            config = PoseNetConfig(**kwargs)
        elif kwargs:
            config = dataclasses.replace(config, **kwargs)
        self.config = config
        self.backbone = build_backbone(config.backbone, config.in_channels, config.num_points)
        c = self.backbone.out_dim
        self.head = nn.Sequential(
            nn.Linear(c, config.hidden), nn.ReLU(inplace=True), nn.Linear(config.hidden, rot.ROTATION_HEADS[config.head].dim)
        )
        self._decode = rot.ROTATION_HEADS[config.head].to_matrix
        # Every head starts at the same prior, an upright mushroom seen from above:
        # R = diag(1, -1, -1) in the OpenCV camera frame (a fair start for the head ablation).
        with torch.no_grad():
            self.head[-1].bias.copy_(torch.tensor(rot.ROTATION_HEADS[config.head].upright))

    def raw(self, x: torch.Tensor) -> torch.Tensor:
        """The head's raw representation ``(B, head_dim)``."""
        if x.dim() != 3 or x.shape[-1] != self.config.in_channels:
            raise ValueError(
                f"x: expected (B, N, {self.config.in_channels}) for use_rgb={self.config.use_rgb}, got {tuple(x.shape)}"
            )
        return self.head(self.backbone(x))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x (B, N, C)`` normalised points (+ rgb) → rotations ``(B, 3, 3)``."""
        return self._decode(self.raw(x))


def save_checkpoint(path: str | Path, model: PoseNet, extra: dict[str, Any] | None = None) -> None:
    """Write ``{format, version, config, state_dict, extra}`` atomically (tmp file + ``os.replace``)."""
    payload = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "config": model.config.to_dict(),
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "extra": extra or {},
    }
    atomic_torch_save(payload, path)


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read and check a checkpoint file's envelope (no model is built)."""
    payload = read_torch_file(path, "pose-network checkpoint")
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointFormatError(f"{path}: not a {CHECKPOINT_FORMAT} checkpoint")
    if payload.get("version") != CHECKPOINT_VERSION:
        raise CheckpointFormatError(f"{path}: version {payload.get('version')!r}, expected {CHECKPOINT_VERSION}")
    return payload


def load_checkpoint(
    path: str | Path, config: PoseNetConfig | None = None, map_location: str | torch.device = "cpu"
) -> tuple[PoseNet, dict[str, Any]]:
    """Rebuild the network stored at ``path``; returns ``(model in eval mode, extra)``.

    If ``config`` is given, every field must equal the stored one, else
    :class:`CheckpointMismatchError` names each differing field.
    """
    payload = read_checkpoint(path)
    stored = PoseNetConfig.from_dict(payload["config"])
    if config is not None:
        _check_fields(path, stored, config, [f.name for f in dataclasses.fields(PoseNetConfig)])
    model = PoseNet(stored)
    try:
        model.load_state_dict(payload["state_dict"])
    except RuntimeError as exc:
        raise CheckpointFormatError(f"{path}: weights do not fit config {stored} ({exc})") from exc
    return model.to(map_location).eval(), payload.get("extra", {})


def load_weights(model: PoseNet, path: str | Path) -> None:
    """Copy every weight stored at ``path`` into ``model`` (fine-tuning). The stored network
    must have ``model``'s shape (every :class:`PoseNetConfig` field but its input fields, e.g.
    ``depth_smoothing_px``, which a fine-tuning run may change), else
    :class:`CheckpointMismatchError`.

    One widening is allowed: an xyz network (``use_rgb=False``) may start an xyz + RGB one of
    a backbone that names its ``input_weight``. The colour columns of that weight start at
    zero, so the new network begins as exactly the stored one and learns what colour adds."""
    payload = read_checkpoint(path)
    stored = PoseNetConfig.from_dict(payload["config"])
    state = payload["state_dict"]
    widen = not stored.use_rgb and model.config.use_rgb and hasattr(model.backbone, "input_weight")
    shape = [f.name for f in dataclasses.fields(PoseNetConfig)
             if f.name not in PoseNetConfig.INPUT_FIELDS and not (widen and f.name == "use_rgb")]
    _check_fields(path, stored, model.config, shape)
    if widen:
        key = f"backbone.{model.backbone.input_weight}"
        xyz_only = state[key]
        wide = torch.zeros(xyz_only.shape[0], model.config.in_channels, dtype=xyz_only.dtype)
        wide[:, : xyz_only.shape[1]] = xyz_only
        state = {**state, key: wide}
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        raise CheckpointFormatError(f"{path}: weights do not fit config {stored} ({exc})") from exc


#: Parameters of the rotation head's output layer, the only ones that depend on the head type.
_OUTPUT_LAYER = ("head.2.weight", "head.2.bias")


def load_backbone(model: PoseNet, path: str | Path) -> None:
    """Copy the backbone and the head's hidden layer stored at ``path`` into ``model``.

    The output layer keeps its fresh (upright-prior) initialisation, so a trained backbone can
    start a network with another rotation head (or re-learn its own). The backbone type, RGB
    input and hidden width must match, else :class:`CheckpointMismatchError`.
    """
    payload = read_checkpoint(path)
    stored = PoseNetConfig.from_dict(payload["config"])
    _check_fields(path, stored, model.config, ["backbone", "use_rgb", "hidden"])
    state = {k: v for k, v in payload["state_dict"].items() if k not in _OUTPUT_LAYER}
    missing, unexpected = model.load_state_dict(state, strict=False)
    if sorted(missing) != sorted(_OUTPUT_LAYER) or unexpected:
        raise CheckpointFormatError(f"{path}: weights do not fit a {stored.backbone} backbone ({missing=}, {unexpected=})")


def _check_fields(path: str | Path, stored: PoseNetConfig, wanted: PoseNetConfig, names: list[str]) -> None:
    mism = {n: (getattr(stored, n), getattr(wanted, n)) for n in names if getattr(stored, n) != getattr(wanted, n)}
    if mism:
        raise CheckpointMismatchError(str(path), mism)
