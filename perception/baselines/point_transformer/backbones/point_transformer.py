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
The forward passes evaluate these formulas in a cheaper order (projections before gathers,
folded biases, late softmax normalisation, CPU batches in chunks, one kNN search shared by the
first attention block and the second transition down) with the same FPS and kNN sets;
``tests/perception/pose/test_backbones.py`` pins them to the plain formulation.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from perception.baselines.point_transformer.backbones.ops import (
    farthest_point_sample,
    flat_index,
    gather_points,
    gather_rows,
    knn,
)


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
        k, G, s = idx.shape[-1], D // self.share, self.share
        pos1, pos2, att1, att2 = self.pos[0], self.pos[2], self.attn[1], self.attn[3]
        flat = flat_index(idx, N)
        # δ_ij = W₂h_ij + b₂ enters as q_i − k_j + δ_ij and v_j + δ_ij: one projection gives
        # q + b₂, −k and v + b₂, so both (B, N, k, D) tensors are a gather plus in-place updates.
        w = torch.cat((self.q.weight, -self.kk.weight, self.v.weight))
        b = torch.cat((self.q.bias + pos2.bias, -self.kk.bias, self.v.bias + pos2.bias))
        qb, neg_k, vb = F.linear(feats, w, b).split(D, dim=-1)
        rel = xyz.unsqueeze(2) - gather_rows(xyz, flat, (B, N, k))
        h = torch.relu_(F.linear(rel, pos1.weight, pos1.bias)).view(-1, 3)  # (B·N·k, 3)
        w2t = pos2.weight.t()
        a = gather_rows(neg_k, flat, (B, N, k)).add_(qb.unsqueeze(2))
        a.view(-1, D).addmm_(h, w2t).relu_()
        logits = F.linear(torch.relu_(F.linear(a, att1.weight, att1.bias)), att2.weight, att2.bias)
        # Softmax over the neighbours, normalised after the weighted sum (k× fewer divisions).
        e = (logits - logits.amax(dim=2, keepdim=True)).exp_()  # (B, N, k, G)
        vd = gather_rows(vb, flat, (B, N, k))
        vd.view(-1, D).addmm_(h, w2t)
        # Channel c = i·G + g uses weight g (channels viewed as (share, G)).
        out = (vd.view(B, N, k, s, G) * e.unsqueeze(3)).sum(2).div_(e.sum(2).unsqueeze(2))
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

    def forward(self, xyz: torch.Tensor, feats: torch.Tensor, idx: torch.Tensor | None = None) -> torch.Tensor:
        """``xyz (B, N, 3)``, ``feats (B, N, D)``; ``idx (B, N, k)``: the points' kNN, if known."""
        if idx is None:
            idx, _ = knn(xyz, xyz, self.k, sorted=False)
        h = torch.relu(self.norm1(self.inp(feats)))
        h = torch.relu(self.norm2(self.layer(xyz, h, idx)))
        return torch.relu(feats + self.out(h))


class TransitionDown(nn.Module):
    """kNN max-pool of ``[p_j − p_i, f_j]`` onto given (FPS) centres, widening ``c_in → c_out``."""

    def __init__(self, c_in: int, c_out: int, k: int = 16) -> None:
        super().__init__()
        self.k = k
        self.mlp = nn.Sequential(nn.Linear(c_in + 3, c_out), nn.LayerNorm(c_out), nn.ReLU(inplace=True))

    def forward(
        self, xyz: torch.Tensor, feats: torch.Tensor, centre_idx: torch.Tensor, idx: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Pool onto ``xyz[centre_idx]``; ``idx (B, M, k)``: the centres' kNN in ``xyz``, if known."""
        centres = gather_points(xyz, centre_idx)
        if idx is None:
            idx, _ = knn(centres, xyz, self.k, sorted=False)
        lin, norm = self.mlp[0], self.mlp[1]
        # W [p_j − p_i, f_j] + b = (W [p_j, f_j] + b) − W_p p_i: project the N source points once
        # and gather the projections, instead of projecting M·k gathered rows.
        src = F.linear(torch.cat((xyz, feats), dim=-1), lin.weight, lin.bias)
        h = gather_points(src, idx).sub_(F.linear(centres, lin.weight[:, :3]).unsqueeze(2))
        # ReLU commutes with the max over the neighbours: apply it to the pooled values.
        return centres, torch.relu(norm(h).amax(dim=2))


class PointTransformer(nn.Module):
    """Point Transformer encoder: embed(32) → TD(N/8, 64) + PT block → TD(N/32, 128) + PT block
    → max-pool; ``out_dim = 128`` (``dims[-1]``)."""

    #: On CPU, clouds are encoded in chunks whose largest tensors (kNN distances and per-neighbour
    #: features, ``N/8 · max(N, k · dims[1])`` floats a cloud) hold about this many floats: 1 MB,
    #: one core's L2 cache here. A batch of 100 at once runs at memory speed instead, and tensors
    #: past glibc's 32 MB mmap threshold pay page faults on every allocation. Measured
    #: interleaved on 2 workers (batch of 100, 512 points): 2^17 / 2^18 / 2^19 floats gave
    #: 125 / 100 / 134 ms medians; at 1024 points 246 / 202 / 242 ms.
    chunk_elements: int = 1 << 18
    #: The parameter that reads the input channels (xyz, then RGB), ``(d0, in_channels)``.
    input_weight: str = "embed.0.weight"

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
        self.neighbour_width = k * d1
        self.embed = nn.Sequential(nn.Linear(in_channels, d0), nn.LayerNorm(d0), nn.ReLU(inplace=True), nn.Linear(d0, d0))
        self.td1 = TransitionDown(d0, d1, k)
        self.pt1 = PointTransformerBlock(d1, k)
        self.td2 = TransitionDown(d1, d2, k)
        self.pt2 = PointTransformerBlock(d2, min(k, self.m2))
        self.out_dim = d2

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x (B, N, C)`` → ``(B, out_dim)``."""
        xyz = x[..., :3].contiguous()
        B, N, _ = xyz.shape
        m1 = min(self.m1, N)
        # One FPS run for the whole batch (its cost is per step, not per cloud); its prefix is
        # the next level's FPS.
        fps = farthest_point_sample(xyz, m1)
        step = B if x.device.type != "cpu" else max(1, self.chunk_elements // (m1 * max(N, self.neighbour_width)))
        if step >= B:
            return self._encode(x, xyz, fps)
        parts = [self._encode(x[i : i + step], xyz[i : i + step], fps[i : i + step]) for i in range(0, B, step)]
        return torch.cat(parts)

    def _encode(self, x: torch.Tensor, xyz: torch.Tensor, fps: torch.Tensor) -> torch.Tensor:
        """The levels after FPS for clouds ``x (b, N, C)`` with their FPS indices ``(b, m1)``."""
        xyz1, f1 = self.td1(xyz, self.embed(x), fps)
        idx1, _ = knn(xyz1, xyz1, self.pt1.k, sorted=False)
        f1 = self.pt1(xyz1, f1, idx1)
        m2 = min(self.m2, fps.shape[1])
        ar = torch.arange(m2, device=x.device).expand(x.shape[0], m2)
        # The level-2 centres are the first m2 level-1 points (FPS prefix), so their kNN among
        # the level-1 points are the first m2 rows of the block's kNN.
        td2_idx = idx1[:, :m2] if self.td2.k == self.pt1.k else None
        xyz2, f2 = self.td2(xyz1, f1, ar, td2_idx)
        f2 = self.pt2(xyz2, f2)
        return f2.amax(dim=1)
