"""Held-out evaluation of a pose checkpoint through :class:`PoseEstimator` (the table in
``perception/weights/README.md``).

Test sets: synthetic single-mushroom views of the training models (ids 0-5, seed 3001) and of
the held-out models (id 6, seed 3002), 500 each; and, with ``--scenes DIR``, every instance of
a rendered scene dataset split (``sms3d generate``), plus the tallest mushroom of each scene
(highest cap top among the instances with enough visible points: the picking environment's
default target). Metrics: geodesic and stem-axis errors (degrees), and the axis error of the
"always upright" prior (stem along -z of the OpenCV camera, i.e. towards a downward camera),
and the mean/median axis error by visible points and by the stem's angle to the camera axis.

    python -m perception.baselines.point_transformer.eval_heldout --scenes runs/pose_scenes_heldout --split test \\
        [--checkpoint PATH] [--json OUT.json] [--plots DIR]

``--plots DIR`` draws the stem-axis error of the training-model views against roll, pitch, yaw
and cap size (:func:`perception.plots.error_plots.plot_errors`, the paper's Figures 9–10).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from perception.baselines.point_transformer.data import PointCloudSample, samples_from_scenes
from perception.baselines.point_transformer.estimator import PoseEstimator, default_weights_path
from perception.baselines.point_transformer.metrics import errors_deg
from perception.baselines.point_transformer.synthetic_views import (
    ViewConfig,
    default_models,
    generate_samples,
)
from perception.plots.error_plots import plot_errors

#: Bins of the breakdowns: visible points of the instance, stem angle to the camera's -z (°).
POINT_BINS = (0, 200, 500, 1000, 2000, 4000, np.inf)
TILT_BINS = (0, 10, 20, 30, 45, 180)


def _by_bin(err: np.ndarray, value: np.ndarray, edges: Sequence[float]) -> dict[str, dict[str, float]]:
    out = {}
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (value >= lo) & (value < hi)
        if m.any():
            out[f"[{lo:g}, {hi:g})"] = {"n": int(m.sum()), "mean_axis_deg": float(err[m].mean()),
                                         "median_axis_deg": float(np.median(err[m]))}  # fmt: skip
    return out


def estimate_errors(est: PoseEstimator, samples: Sequence[PointCloudSample], batch: int = 64) -> dict[str, np.ndarray]:
    """Per-sample errors in degrees: ``geodesic``, stem ``axis``, and ``upright`` (the axis
    error of the "always upright" prior, i.e. the stem's angle to the camera's -z)."""
    preds = []
    for i in range(0, len(samples), batch):
        preds += [e.rotation for e in est.estimate_batch([s.points for s in samples[i : i + batch]])]
    R_pred = np.stack(preds)
    R_gt = np.stack([np.asarray(s.rotation, dtype=np.float64) for s in samples])
    geodesic, axis = errors_deg(torch.from_numpy(R_pred), torch.from_numpy(R_gt))
    stem = R_gt[:, :, 2] / np.linalg.norm(R_gt[:, :, 2], axis=1, keepdims=True)
    return {"geodesic": geodesic, "axis": axis, "upright": np.degrees(np.arccos(np.clip(-stem[:, 2], -1.0, 1.0)))}


def _metrics(samples: Sequence[PointCloudSample], err: dict[str, np.ndarray], seconds: float) -> dict[str, float]:
    geo, ax, up = err["geodesic"], err["axis"], err["upright"]
    return {
        "n": len(samples),
        "mean_geodesic_deg": float(geo.mean()),
        "median_geodesic_deg": float(np.median(geo)),
        "mean_axis_deg": float(ax.mean()),
        "median_axis_deg": float(np.median(ax)),
        "p90_axis_deg": float(np.percentile(ax, 90)),
        "upright_prior_mean_axis_deg": float(up.mean()),
        "seconds": seconds,
        "by_visible_points": _by_bin(ax, np.array([s.meta.get("num_valid", len(s.points)) for s in samples]), POINT_BINS),
        "by_tilt_to_camera_deg": _by_bin(ax, up, TILT_BINS),
    }


def evaluate_set(est: PoseEstimator, samples: Sequence[PointCloudSample]) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    """Summary metrics (the README table's columns and breakdowns) and per-sample errors."""
    t = time.perf_counter()
    err = estimate_errors(est, samples)
    return _metrics(samples, err, time.perf_counter() - t), err


def tallest_per_scene(root: str | Path, samples: Sequence[PointCloudSample]) -> list[PointCloudSample]:
    """The sample of each scene whose instance has the highest cap top (world z)."""
    best: dict[int, tuple[float, PointCloudSample]] = {}
    for s in samples:
        sid, iid = s.meta["scene_id"], s.meta["instance_id"]
        record = json.loads((Path(root) / f"scene_{sid:06d}" / "scene.json").read_text())
        inst = next(m for m in record["instances"] if m["id"] == iid)
        z = float(inst["cap_top"][2])
        if sid not in best or z > best[sid][0]:
            best[sid] = (z, s)
    return [best[k][1] for k in sorted(best)]


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m perception.baselines.point_transformer.eval_heldout")
    p.add_argument("--checkpoint", help="default: the shipped weights")
    p.add_argument("--scenes", help="rendered scene dataset folder")
    p.add_argument("--split", default="test", help="scene split ('all' for every scene)")
    p.add_argument("--no-synthetic", action="store_true", help="skip the synthetic-view sets")
    p.add_argument("--num", type=int, default=500, help="synthetic views per set")
    p.add_argument("--camera-model", action="store_true",
                   help="synthetic views through the dataset's stereo camera model (ViewConfig camera_model)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--views", type=int, default=1, help="test-time views averaged per cloud (PoseEstimator views)")
    p.add_argument("--upright-pass", action="store_true", help="PoseEstimator upright_pass: views again on the uprighted cloud")
    p.add_argument("--json", help="also write the results here")
    p.add_argument("--plots", help="folder for stem-axis error vs roll/pitch/yaw and vs cap size (synthetic training-model views)")
    args = p.parse_args(argv)
    if args.plots and args.no_synthetic:
        p.error("--plots draws the synthetic training-model views: drop --no-synthetic")
    if args.camera_model and args.no_synthetic:
        p.error("--camera-model applies to the synthetic views: drop --no-synthetic")
    torch.set_num_threads(args.threads)
    path = Path(args.checkpoint) if args.checkpoint else default_weights_path()
    est = PoseEstimator.from_checkpoint(path, sampling="random", seed=0, views=args.views, upright_pass=args.upright_pass)
    out: dict[str, dict[str, float]] = {}
    if not args.no_synthetic:
        views = ViewConfig(camera_model=args.camera_model)
        camera = ", camera model" if args.camera_model else ""
        for label, seed, ids in ((f"synthetic views{camera}, training models (ids 0-5), seed 3001", 3001, (0, 1, 2, 3, 4, 5)),
                                 (f"synthetic views{camera}, held-out models (id 6), seed 3002", 3002, (6,))):
            samples = generate_samples(args.num, seed, default_models(model_ids=ids), views)
            out[label], err = evaluate_set(est, samples)
            print(label, json.dumps(out[label]), flush=True)
            if args.plots and seed == 3001:
                title = f"{path.name}, {args.views} view{'s' if args.views > 1 else ''}, {len(samples)} synthetic views"
                for png in plot_errors({"stem axis": err["axis"]}, [s.meta for s in samples], args.plots, title):
                    print(f"wrote {png}", flush=True)
    if args.scenes:
        split = None if args.split == "all" else args.split
        samples = samples_from_scenes(args.scenes, split, seed=0)
        for label, ss in ((f"scenes {args.scenes} ({args.split}), every instance", samples),
                          (f"scenes {args.scenes} ({args.split}), tallest mushroom per scene",
                           tallest_per_scene(args.scenes, samples))):
            out[label], _ = evaluate_set(est, ss)
            print(label, json.dumps(out[label]), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"checkpoint": str(path), "views": args.views, "upright_pass": args.upright_pass, "results": out}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
