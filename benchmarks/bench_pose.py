"""Pose-network inference speed: ms per mushroom (batch 1) and per batch of 100, per backbone.

Targets (SMS3D Table 1 was measured on a GPU): <= 5.5 ms per 1024-point mushroom and
<= 100 ms per batch of 100. Prints one Markdown table; run ``python benchmarks/bench_pose.py``.
Times are medians over ``--repeats`` runs after a warm-up of ``PoseEstimator.infer`` (eval mode,
``inference_mode``); ``--workers W`` splits batches over W threads, each with ``--threads``
intra-op threads (``--threads 1 --workers 2`` suits a 2-core CPU).
"""

from __future__ import annotations

import argparse
import io
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # runs from a checkout

from perception.baselines.point_transformer.estimator import PoseEstimator  # noqa: E402
from perception.baselines.point_transformer.pose_net import PoseNet, PoseNetConfig  # noqa: E402


def time_ms(estimator: PoseEstimator, x: torch.Tensor, repeats: int) -> float:
    estimator.infer(x)
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        estimator.infer(x)
        ts.append((time.perf_counter() - t) * 1e3)
    return statistics.median(ts)


def weights_mb(model: PoseNet) -> float:
    buf = io.BytesIO()
    torch.save(model.state_dict(), buf)
    return buf.tell() / 2**20


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--threads", type=int, default=2, help="intra-op threads (torch.set_num_threads)")
    p.add_argument("--workers", type=int, default=1, help="threads a batch is split over (PoseEstimator workers)")
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--points", type=int, nargs="+", default=[64, 256, 512, 1024])
    p.add_argument("--backbones", nargs="+", default=["point_transformer", "pointnet", "pointnet2"])
    p.add_argument("--device", default="cpu")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    print(f"device={args.device} threads={torch.get_num_threads()} workers={args.workers} torch={torch.__version__}\n")
    print("| backbone | points | params | weights MB | ms / mushroom (B=1) | ms / batch of 100 | ms / mushroom in batch |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for bb in args.backbones:
        for n in args.points:
            model = PoseNet(PoseNetConfig(backbone=bb, num_points=n)).to(args.device).eval()
            estimator = PoseEstimator(model, args.device, workers=args.workers)
            x1 = torch.rand(1, n, 3, device=args.device) * 2 - 1
            x100 = torch.rand(100, n, 3, device=args.device) * 2 - 1
            t1 = time_ms(estimator, x1, args.repeats)
            t100 = time_ms(estimator, x100, max(3, args.repeats // 5))
            npar = sum(q.numel() for q in model.parameters())
            print(f"| {bb} | {n} | {npar:,} | {weights_mb(model):.2f} | {t1:.2f} | {t100:.1f} | {t100 / 100:.2f} |", flush=True)


if __name__ == "__main__":
    main()
