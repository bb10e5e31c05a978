"""Point Transformer (Zhao et al., ICCV 2021), classification-style encoder in plain torch.

- Point Transformer layer: vector self-attention over the ``k`` nearest neighbours,
  ``y_i = Σ_j softmax_j(γ(φ(x_i) − ψ(x_j) + δ_ij)) ⊙ (α(x_j) + δ_ij)`` with the relative
  position encoding ``δ_ij = θ(p_i − p_j)`` (a two-layer MLP) and ``γ`` an MLP, softmax per
  channel over the neighbours; wrapped in a residual block with linear in/out projections.
- Transition down: farthest-point sampling of the centres, kNN grouping of
  ``[p_j − p_i, f_j]`` from the finer level, a linear layer and a max-pool.
- Global feature: max-pool over the coarsest level.

Sizes are modest so that 1024-point inference is a few milliseconds on a CPU: a per-point
embedding (no attention at full resolution), then N → N/8 → N/32 with attention at both levels.
"""

from __future__ import annotations

import torch
from torch import nn

from perception.backbones.ops import farthest_point_sample, gather_points, knn


class PointTransformerLayer(nn.Module):
    """Vector self-attention over kNN neighbourhoods with a relative position encoding.

    As in the authors' reference code: ``δ = Linear(ReLU(Linear(p_i − p_j)))`` (3 → 3 → D) and the
    attention MLP ``γ`` maps to ``D / share`` weights, each shared by ``share`` channels
    (grouped vector attention), which keeps the cost per neighbour small.
    """

    def __init__(self, dim: int, k: int = 16, share: int = 8) -> None:
        super().__init__()
        if dim % share:
            raise ValueError(f"dim: {dim} is not divisible by share={share}")
        self.k, self.share = k, share
        self.q, self.kk, self.v = nn.Linear(dim, dim), nn.Linear(dim, dim), nn.Linear(dim, dim)
        self.pos = nn.Sequential(nn.Linear(3, 3), nn.ReLU(inplace=True), nn.Linear(3, dim))
        self.attn = nn.Sequential(
            nn.ReLU(), nn.Linear(dim, dim // share), nn.ReLU(inplace=True), nn.Linear(dim // share, dim // share)
        )

    def forward(self, xyz: torch.Tensor, feats: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
        """``xyz (B, N, 3)``, ``feats (B, N, D)``, neighbour ``idx (B, N, k)`` → ``(B, N, D)``."""
        B, N, D = feats.shape
        q = self.q(feats)
        k = gather_points(self.kk(feats), idx)
        v = gather_points(self.v(feats), idx)
        delta = self.pos(xyz.unsqueeze(2) - gather_points(xyz, idx))
        w = torch.softmax(self.attn(q.unsqueeze(2) - k + delta), dim=2)  # (B, N, k, D/share)
        out = ((v + delta).view(B, N, -1, self.share, D // self.share) * w.unsqueeze(3)).sum(dim=2)
        return out.reshape(B, N, D)


class PointTransformerBlock(nn.Module):
    """Residual block: linear → Point Transformer layer → linear, with LayerNorm."""

    def __init__(self, dim: int, k: int = 16) -> None:
        super().__init__()
        self.inp = nn.Linear(dim, dim)
        self.layer = PointTransformerLayer(dim, k)
        self.out = nn.Linear(dim, dim)
        self.norm1, self.norm2 = nn.LayerNorm(dim), nn.LayerNorm(dim)
        self.k = k

    def forward(self, xyz: torch.Tensor, feats: torch.Tensor) -> torch.Tensor:
        idx, _ = knn(xyz, xyz, self.k)
        h = torch.relu(self.norm1(self.inp(feats)))
        h = torch.relu(self.norm2(self.layer(xyz, h, idx)))
        return torch.relu(feats + self.out(h))


class TransitionDown(nn.Module):
    """kNN max-pool of ``[p_j − p_i, f_j]`` onto given (FPS) centres, widening ``c_in → c_out``."""

    def __init__(self, c_in: int, c_out: int, k: int = 16) -> None:
        super().__init__()
        self.k = k
        self.mlp = nn.Sequential(nn.Linear(c_in + 3, c_out), nn.LayerNorm(c_out), nn.ReLU(inplace=True))

    def forward(self, xyz: torch.Tensor, feats: torch.Tensor, centre_idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        centres = gather_points(xyz, centre_idx)
        idx, _ = knn(centres, xyz, self.k)
        rel = gather_points(xyz, idx) - centres.unsqueeze(2)
        grouped = torch.cat((rel, gather_points(feats, idx)), dim=-1)
        return centres, self.mlp(grouped).max(dim=2).values


class PointTransformer(nn.Module):
    """Point Transformer encoder: embed(32) → TD(N/8, 64) + PT block → TD(N/32, 128) + PT block
    → max-pool; ``out_dim = 128`` (``dims[-1]``)."""

    def __init__(
        self,
        in_channels: int = 3,
        num_points: int = 1024,
        dims: tuple[int, int, int] = (32, 64, 128),
        k: int = 16,
    ) -> None:
        super().__init__()
        d0, d1, d2 = dims
        self.m1 = max(num_points // 8, min(num_points, 16))
        self.m2 = max(self.m1 // 4, min(self.m1, 8))
        self.embed = nn.Sequential(nn.Linear(in_channels, d0), nn.LayerNorm(d0), nn.ReLU(inplace=True), nn.Linear(d0, d0))
        self.td1 = TransitionDown(d0, d1, k)
        self.pt1 = PointTransformerBlock(d1, k)
        self.td2 = TransitionDown(d1, d2, k)
        self.pt2 = PointTransformerBlock(d2, min(k, self.m2))
        self.out_dim = d2

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x (B, N, C)`` → ``(B, out_dim)``."""
        xyz = x[..., :3].contiguous()
        f0 = self.embed(x)
        m1 = min(self.m1, xyz.shape[1])
        fps = farthest_point_sample(xyz, m1)  # one run; its prefix is the next level's FPS
        xyz1, f1 = self.td1(xyz, f0, fps)
        f1 = self.pt1(xyz1, f1)
        m2 = min(self.m2, m1)
        ar = torch.arange(m2, device=x.device).expand(x.shape[0], m2)
        xyz2, f2 = self.td2(xyz1, f1, ar)
        f2 = self.pt2(xyz2, f2)
        return f2.max(dim=1).values
