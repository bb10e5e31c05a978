"""How much stem-axis information does a camera-model depth view still hold, and how much of it
does the shipped pose network read?

For each single-mushroom view (``perception.baselines.point_transformer.synthetic_views.render_view``, unseen procedural
shapes), its points are fitted to its *own* mesh (the true shape, scale and stretch): the rms
point-to-mesh distance with the true rotation, and with the true rotation tilted by θ about a
random axis perpendicular to the stem (the translation re-fitted each time, so a tilt cannot
hide behind a shift). A view "tells θ apart" when the true pose fits better than the tilted
one. This is an upper bound on what an estimator that knows the shape could read; the shipped
network's axis error on the same views is printed beside it.

Usage: python benchmarks/bench_axis_information.py [--views 200] [--tilts 3 6 10 15] [--seed 5000]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # runs from a checkout

import numpy as np  # noqa: E402
import trimesh  # noqa: E402
from tqdm import tqdm  # noqa: E402

from perception.baselines.point_transformer.estimator import PoseEstimator  # noqa: E402
from perception.baselines.point_transformer.synthetic_views import (  # noqa: E402
    CAMERA_FROM_WORLD,
    MeshModel,
    ViewConfig,
    posed_mesh,
    procedural_mesh_models,
    render_view,
)
from perception.pointcloud import MIN_POINTS  # noqa: E402

#: Points per view used in the fit (a random subset; the fit's cost grows with it).
FIT_POINTS = 300
#: Translation re-fits per rotation (each: the mean offset of the points from their closest
#: mesh points).
TRANSLATION_STEPS = 6


def fit_rms(mesh: trimesh.Trimesh, points: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> float:
    """rms distance (m) of camera-frame ``points (N, 3)`` to ``mesh`` posed by ``rotation`` (3, 3)
    and the best translation near ``translation`` (3,)."""
    t = translation
    for _ in range(TRANSLATION_STEPS):
        local = (points - t) @ rotation
        closest, _, _ = trimesh.proximity.closest_point(mesh, local)
        t = t + rotation @ (local - closest).mean(0)
    _, distance, _ = trimesh.proximity.closest_point(mesh, (points - t) @ rotation)
    return float(np.sqrt(np.mean(distance**2)))


def _axis_error_deg(rotation: np.ndarray, truth: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(rotation[:, 2] @ truth[:, 2], -1.0, 1.0))))


def measure(camera_model: bool, views: int, tilts: list[float], seed: int, models: list[MeshModel],
            estimator: PoseEstimator) -> dict[str, float]:
    """Per tilt the share of views that tell it apart; the network's mean / median axis error."""
    config = ViewConfig(camera_model=camera_model)
    told_apart: dict[float, list[bool]] = {t: [] for t in tilts}
    network: list[float] = []
    for i in tqdm(range(views), desc=f"camera_model={camera_model}", leave=False):
        model = models[i % len(models)]
        sample = render_view(model, np.random.default_rng(seed + i), config)
        if len(sample.points) < MIN_POINTS:
            continue
        truth = sample.rotation.astype(np.float64)
        translation = CAMERA_FROM_WORLD @ (np.asarray(sample.meta["position_world"])
                                           - np.array([0.0, 0.0, config.camera_height]))
        mesh = posed_mesh(model, sample.meta)
        rng = np.random.default_rng(seed + i + 1)
        points = sample.points.astype(np.float64)
        points = points[rng.choice(len(points), min(FIT_POINTS, len(points)), replace=False)]
        at_truth = fit_rms(mesh, points, truth, translation)
        tilt_axis = rng.normal(size=3)
        tilt_axis -= (tilt_axis @ truth[:, 2]) * truth[:, 2]
        tilt_axis /= np.linalg.norm(tilt_axis)
        for t in tilts:
            tilted = trimesh.transformations.rotation_matrix(np.radians(t), tilt_axis)[:3, :3] @ truth
            told_apart[t].append(at_truth < fit_rms(mesh, points, tilted, translation))
        network.append(_axis_error_deg(estimator.estimate(sample.points).rotation, truth))
    return {"views": len(network), "network_mean": float(np.mean(network)),
            "network_median": float(np.median(network)),
            **{f"tilt_{t:g}": float(np.mean(told_apart[t])) for t in tilts}}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--views", type=int, default=200)
    ap.add_argument("--tilts", type=float, nargs="+", default=[3.0, 6.0, 10.0, 15.0])
    ap.add_argument("--seed", type=int, default=5000)
    args = ap.parse_args(argv)
    estimator = PoseEstimator.from_pretrained(views=8)
    models = procedural_mesh_models(20, seed=424242)  # shapes no shipped network was trained on
    head = " | ".join(f"tells {t:g}° apart" for t in args.tilts)
    print(f"| depth | views | {head} | shipped network: mean / median axis error |")
    print("| --- | ---: |" + " ---: |" * len(args.tilts) + " --- |")
    for camera_model in (False, True):
        r = measure(camera_model, args.views, args.tilts, args.seed, models, estimator)
        shares = " | ".join(f"{r[f'tilt_{t:g}']:.0%}" for t in args.tilts)
        print(f"| {'camera model (D405)' if camera_model else 'clean'} | {r['views']} | {shares} | "
              f"{r['network_mean']:.1f}° / {r['network_median']:.1f}° |", flush=True)


if __name__ == "__main__":
    main()
