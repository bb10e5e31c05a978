"""Train the mushroom pose network on rendered single-mushroom views, then use it.

    python examples/train_pose.py --out runs/pose_quick            # a few minutes on a CPU
    # (this quick size barely beats the "always upright" prior, ~25° stem-axis error; the
    #  shipped weights' 30-minute recipe is in perception/weights/README.md)
    python examples/train_pose.py --out runs/pose --num-train 4000 --epochs 50 --num-points 1024

Renders views of the generator's mushroom models (held-out model 6 of each species is kept for
testing), trains a Point Transformer with a 6D head, reports mean geodesic and stem-axis errors
on held-out seeds, and runs the trained network through ``PoseEstimator``.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from perception.baselines.point_transformer.data import PointCloudPoseDataset
from perception.baselines.point_transformer.estimator import PoseEstimator
from perception.baselines.point_transformer.pose_net import PoseNetConfig
from perception.baselines.point_transformer.synthetic_views import default_models, generate_samples
from perception.baselines.point_transformer.train import TrainConfig, evaluate, train


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="runs/pose_quick")
    p.add_argument("--num-train", type=int, default=800)
    p.add_argument("--num-points", type=int, default=256)
    p.add_argument("--epochs", type=int, default=10)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args()
    torch.set_num_threads(args.threads)

    seen = default_models(model_ids=range(6))
    unseen = default_models(model_ids=(6,))
    train_s = generate_samples(args.num_train, seed=1, models=seen)
    val_s = generate_samples(200, seed=2, models=seen)
    test_seen, test_unseen = generate_samples(200, seed=3, models=seen), generate_samples(200, seed=4, models=unseen)

    net = PoseNetConfig(backbone="point_transformer", head="6d", num_points=args.num_points)
    cfg = TrainConfig(epochs=args.epochs, lr=args.lr, loss="geodesic+axis")
    model, _ = train(
        net, cfg, PointCloudPoseDataset(train_s, net.num_points, augment=cfg.augment), PointCloudPoseDataset(val_s, net.num_points), args.out
    )
    for name, s in (("seen models", test_seen), ("held-out models", test_unseen)):
        _, m, *_ = evaluate(model, PointCloudPoseDataset(s, net.num_points, seed=7))
        print(f"{name}: geodesic {m.mean_geodesic_deg:.1f}° (median {m.median_geodesic_deg:.1f}°), "
              f"stem axis {m.mean_axis_deg:.1f}° (median {m.median_axis_deg:.1f}°)")

    est = PoseEstimator(model)
    e = est.estimate(test_unseen[0].points)
    true_axis = test_unseen[0].rotation[:, 2]
    err = np.degrees(np.arccos(np.clip(e.stem_axis @ true_axis, -1, 1)))
    print(f"one mushroom: centre {np.round(e.centre, 3)} m, stem axis {np.round(e.stem_axis, 3)}, error {err:.1f}°")


if __name__ == "__main__":
    main()
