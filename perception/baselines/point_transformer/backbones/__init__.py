"""Point-cloud backbones: ``(B, N, C)`` points (xyz first, optional rgb) → ``(B, out_dim)``.

All are plain PyTorch (CPU and CUDA), invariant to the order of the input points in eval mode.
"""

from __future__ import annotations

from torch import nn

from perception.baselines.point_transformer.backbones.point_transformer import PointTransformer
from perception.baselines.point_transformer.backbones.pointnet import PointNet
from perception.baselines.point_transformer.backbones.pointnet2 import PointNet2

BACKBONES: dict[str, type[nn.Module]] = {
    "point_transformer": PointTransformer,
    "pointnet": PointNet,
    "pointnet2": PointNet2,
}


def build_backbone(name: str, in_channels: int, num_points: int) -> nn.Module:
    """Construct the backbone ``name`` (one of :data:`BACKBONES`)."""
    if name not in BACKBONES:
        raise ValueError(f"backbone: expected one of {sorted(BACKBONES)}, got {name!r}")
    return BACKBONES[name](in_channels=in_channels, num_points=num_points)


__all__ = ["BACKBONES", "PointNet", "PointNet2", "PointTransformer", "build_backbone"]
