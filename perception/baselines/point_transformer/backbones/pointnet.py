"""PointNet (Qi et al., CVPR 2017) without the input/feature transform nets.

A shared per-point MLP followed by a symmetric max-pool: order invariant by construction.
"""

from __future__ import annotations

import torch
from torch import nn


class PointNet(nn.Module):
    """Shared MLP ``in → 64 → 128 → 256`` per point, then max-pool to ``out_dim = 256``."""

    #: The parameter that reads the input channels (xyz, then RGB), ``(widths[0], in_channels)``.
    input_weight: str = "mlp.0.weight"

    def __init__(self, in_channels: int = 3, num_points: int = 1024, widths: tuple[int, ...] = (64, 128, 256)) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        c = in_channels
        for w in widths:
            layers += [nn.Linear(c, w), nn.ReLU(inplace=True)]
            c = w
        self.mlp = nn.Sequential(*layers)
        self.out_dim = c

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x (B, N, C)`` → ``(B, out_dim)``."""
        return self.mlp(x).amax(dim=1)
