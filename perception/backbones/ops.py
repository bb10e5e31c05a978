"""Batched point operations in plain torch: farthest-point sampling, kNN, gathering."""

from __future__ import annotations

import torch


def farthest_point_sample(xyz: torch.Tensor, m: int) -> torch.Tensor:
    """Indices ``(B, m)`` of farthest-point samples of ``xyz (B, N, 3)``.

    Starts at the point farthest from the centroid, so the selected set does not depend on the
    input order (up to exact distance ties). Any prefix of the result is itself an FPS of that
    size, which lets coarser levels reuse one run.
    """
    B, N, _ = xyz.shape
    if m > N:
        raise ValueError(f"m: cannot sample {m} of {N} points")
    xt = xyz.detach().transpose(1, 2).contiguous()  # (B, 3, N): contiguous rows are faster
    centroid = xt.mean(2, keepdim=True)
    far = ((xt - centroid) ** 2).sum(1).argmax(1)
    dist = torch.full((B, N), float("inf"), device=xyz.device, dtype=xyz.dtype)
    idx = torch.empty(B, m, dtype=torch.long, device=xyz.device)
    for i in range(m):
        idx[:, i] = far
        p = torch.gather(xt, 2, far.view(B, 1, 1).expand(B, 3, 1))
        torch.minimum(dist, ((xt - p) ** 2).sum(1), out=dist)
        far = dist.argmax(1)
    return idx


def gather_points(x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """``x (B, N, C)`` gathered at ``idx (B, ...)`` → ``(B, ..., C)``."""
    B = x.shape[0]
    flat = idx.reshape(B, -1)
    out = torch.gather(x, 1, flat.unsqueeze(-1).expand(-1, -1, x.shape[-1]))
    return out.reshape(*idx.shape, x.shape[-1])


def knn(query: torch.Tensor, ref: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``k`` nearest ``ref (B, N, 3)`` points of each ``query (B, M, 3)``: (indices, sq. dists)."""
    d = torch.cdist(query, ref).square_()
    dist, idx = d.topk(min(k, ref.shape[1]), dim=-1, largest=False, sorted=True)
    return idx, dist
