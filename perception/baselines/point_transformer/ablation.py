"""Ablation runner: points, rotation heads, RGB and backbones, as in SMS3D Tables 1–3.

Each variant is trained with the same data, seeds and optimiser settings, then evaluated on a
held-out set; results go to ``OUT/ablation.md`` (a Markdown table of mean/median geodesic and
stem-axis errors and batch-1 inference ms) and ``OUT/ablation.json``. For the first variant
(the default network) it also plots error against roll, pitch, yaw and cap size
(``OUT/error_vs_angles.png``, ``OUT/error_vs_size.png``). Rerunning with the same ``--out``
and settings resumes: variants already in ``OUT/ablation.json`` are not trained again.

Run: ``python -m perception.baselines.point_transformer.ablation --out runs/ablation`` (see ``--help`` for sizes).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from generator.files import write_atomic
from perception.baselines.point_transformer.data import PointCloudPoseDataset, PointCloudSample
from perception.baselines.point_transformer.pose_net import PoseNet, PoseNetConfig
from perception.baselines.point_transformer.synthetic_views import (
    ViewConfig,
    default_models,
    generate_samples,
)
from perception.baselines.point_transformer.train import TrainConfig, evaluate, train
from perception.plots.error_plots import plot_errors


@dataclass(frozen=True)
class Variant:
    """One ablation cell: the study it belongs to and the network it trains."""

    study: str
    net: PoseNetConfig

    @property
    def name(self) -> str:
        n = self.net
        return f"{n.backbone}-{n.head}-{'rgb' if n.use_rgb else 'xyz'}-{n.num_points}"


def default_variants(base_points: int = 1024, points: Sequence[int] = (64, 256, 1024)) -> list[Variant]:
    """The paper's studies around the default (Point Transformer, 6D, no RGB), de-duplicated."""
    base = PoseNetConfig(num_points=base_points)
    out = [Variant("default", base)]
    out += [Variant("points", PoseNetConfig(num_points=n)) for n in points]
    out += [Variant("head", PoseNetConfig(head=h, num_points=base_points)) for h in ("6d_stem", "9d", "quat", "euler")]
    out += [Variant("rgb", PoseNetConfig(use_rgb=True, num_points=base_points))]
    out += [Variant("backbone", PoseNetConfig(backbone=b, num_points=base_points)) for b in ("pointnet", "pointnet2")]
    seen, unique = set(), []
    for v in out:
        if v.net not in seen:
            seen.add(v.net)
            unique.append(v)
    return unique


def inference_ms(model: PoseNet, repeats: int = 10) -> float:
    x = torch.rand(1, model.config.num_points, model.config.in_channels)
    with torch.no_grad():
        model(x)
        t = time.perf_counter()
        for _ in range(repeats):
            model(x)
    return (time.perf_counter() - t) / repeats * 1e3


def run_ablation(
    variants: Sequence[Variant],
    train_samples: Sequence[PointCloudSample],
    val_samples: Sequence[PointCloudSample],
    test_samples: Sequence[PointCloudSample],
    train_config: TrainConfig,
    out_dir: str | Path,
) -> list[dict]:
    """Train and evaluate every variant; write the table, JSON and plots; return the rows."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    settings = {"train": train_config.to_dict(), "samples": [len(train_samples), len(val_samples), len(test_samples)]}
    settings_path, rows_path = out / "ablation_settings.json", out / "ablation.json"
    done: dict[str, dict] = {}
    if rows_path.exists():
        stored = json.loads(settings_path.read_text()) if settings_path.exists() else None
        if stored != json.loads(json.dumps(settings, default=str)):
            raise ValueError(f"{out}: holds an ablation run with other settings ({stored}); use another output folder")
        done = {r["variant"]: r for r in json.loads(rows_path.read_text())}
    write_atomic(settings_path, json.dumps(settings, indent=2, default=str))
    rows = []
    for i, v in enumerate(variants):
        if v.name in done:
            rows.append(done[v.name])
            continue
        n = v.net
        t = time.perf_counter()
        tr = PointCloudPoseDataset(train_samples, n.num_points, n.use_rgb, train_config.augment, seed=train_config.seed)
        va = PointCloudPoseDataset(val_samples, n.num_points, n.use_rgb, None, seed=train_config.seed + 1)
        te = PointCloudPoseDataset(test_samples, n.num_points, n.use_rgb, None, seed=train_config.seed + 2)
        model, log = train(n, train_config, tr, va, out / v.name)
        _, m, g, a, idx = evaluate(model, te)
        row = {"study": v.study, "variant": v.name, **n.to_dict(), **m.as_dict(),
               "inference_ms": inference_ms(model), "epochs": len(log), "train_s": time.perf_counter() - t}  # fmt: skip
        rows.append(row)
        print(f"[{i + 1}/{len(variants)}] {v.name}: geo {m.mean_geodesic_deg:.2f}° axis {m.mean_axis_deg:.2f}°", file=sys.stderr)
        if i == 0:
            meta = [te.samples[j].meta for j in idx]
            plot_errors({"geodesic": g, "stem axis": a}, meta, out, title=v.name)
        write_atomic(rows_path, json.dumps(rows, indent=2))
        write_atomic(out / "ablation.md", markdown_table(rows))
    return rows


def markdown_table(rows: Sequence[dict]) -> str:
    lines = [
        "| study | backbone | head | RGB | points | mean geodesic ° | median geodesic ° | mean axis ° | median axis ° | inference ms (B=1) |",
        "|---|---|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['study']} | {r['backbone']} | {r['head']} | {'yes' if r['use_rgb'] else 'no'} | {r['num_points']} | "
            f"{r['mean_geodesic_deg']:.2f} | {r['median_geodesic_deg']:.2f} | {r['mean_axis_deg']:.2f} | "
            f"{r['median_axis_deg']:.2f} | {r['inference_ms']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m perception.baselines.point_transformer.ablation", description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True)
    p.add_argument("--num-train", type=int, default=4000)
    p.add_argument("--num-val", type=int, default=400)
    p.add_argument("--num-test", type=int, default=500)
    p.add_argument("--epochs", type=int, default=10)
    p.add_argument("--lr", type=float, default=1e-4)
    p.add_argument("--loss", default="geodesic", choices=("geodesic", "axis", "geodesic+axis"))
    p.add_argument("--base-points", type=int, default=1024)
    p.add_argument("--points", type=int, nargs="+", default=[64, 256, 1024])
    p.add_argument("--only", nargs="+", help="run only these studies (default, points, head, rgb, backbone)")
    p.add_argument("--tilt-std-deg", type=float, default=20.0, help="σ of roll/pitch of the rendered views")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--device", default="cpu")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    variants = default_variants(args.base_points, args.points)
    if args.only:
        variants = [v for v in variants if v.study in args.only]
    train_models = default_models(model_ids=(0, 1, 2, 3, 4, 5))
    views = ViewConfig(tilt_std_deg=args.tilt_std_deg)
    tr = generate_samples(args.num_train, args.seed * 1000 + 1, train_models, views)
    va = generate_samples(args.num_val, args.seed * 1000 + 2, train_models, views)
    te = generate_samples(args.num_test, args.seed * 1000 + 3, default_models(), views)  # all models
    cfg = TrainConfig(epochs=args.epochs, lr=args.lr, loss=args.loss, seed=args.seed, device=args.device, progress=False)
    run_ablation(variants, tr, va, te, cfg, args.out)
    print((Path(args.out) / "ablation.md").read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
