"""PointNet++ with single-scale grouping (Qi et al., NeurIPS 2017), plain torch.

Two set-abstraction levels (FPS centres, ball-query grouping of ``nsample`` neighbours, shared
MLP on ``[relative xyz, features]``, max-pool) and a global level that pools everything. Ball
query is kNN restricted to the radius (out-of-radius neighbours replaced by the nearest one,
as in the reference CUDA op). Coordinates are expected in the unit sphere.
"""

from __future__ import annotations

import torch
from torch import nn

from perception.baselines.point_transformer.backbones.ops import (
    farthest_point_sample,
    gather_points,
    knn,
)


def _mlp(c_in: int, widths: tuple[int, ...]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for w in widths:
        layers += [nn.Linear(c_in, w), nn.LayerNorm(w), nn.ReLU(inplace=True)]
        c_in = w
    return nn.Sequential(*layers)


class SetAbstraction(nn.Module):
    """One SSG level: ``(xyz, feats)`` at N points → ``(xyz, feats)`` at ``npoint`` centres."""

    def __init__(self, radius: float, nsample: int, c_in: int, widths: tuple[int, ...]) -> None:
        super().__init__()
        self.radius, self.nsample = radius, nsample
        self.mlp = _mlp(c_in + 3, widths)
        self.out_dim = widths[-1]

    def forward(self, xyz: torch.Tensor, feats: torch.Tensor, centre_idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        centres = gather_points(xyz, centre_idx)  # (B, M, 3)
        idx, d2 = knn(centres, xyz, self.nsample)  # (B, M, k)
        idx = torch.where(d2 <= self.radius**2, idx, idx[..., :1])
        rel = (gather_points(xyz, idx) - centres.unsqueeze(2)) / self.radius
        grouped = torch.cat((rel, gather_points(feats, idx)), dim=-1)
        return centres, self.mlp(grouped).amax(dim=2)


class PointNet2(nn.Module):
    """SSG PointNet++: SA(N/8, r=0.2, 32) → SA(N/32, r=0.4, 32) → global SA; ``out_dim = 256``."""

    def __init__(self, in_channels: int = 3, num_points: int = 1024) -> None:
        super().__init__()
        self.m1 = max(num_points // 8, min(num_points, 16))
        self.m2 = max(self.m1 // 4, min(self.m1, 8))
        self.sa1 = SetAbstraction(0.2, 32, in_channels, (32, 32, 64))
        self.sa2 = SetAbstraction(0.4, 32, 64, (64, 64, 128))
        self.sa3 = _mlp(128 + 3, (128, 256))
        self.out_dim = 256

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x (B, N, C)`` → ``(B, 256)``."""
        xyz = x[..., :3].contiguous()
        m1 = min(self.m1, xyz.shape[1])
        fps = farthest_point_sample(xyz, m1)  # one run; its prefix serves the second level
        xyz1, f1 = self.sa1(xyz, x, fps)
        m2 = min(self.m2, m1)
        ar = torch.arange(m2, device=x.device).expand(x.shape[0], m2)
        xyz2, f2 = self.sa2(xyz1, f1, ar)
        return self.sa3(torch.cat((xyz2, f2), dim=-1)).amax(dim=1)
