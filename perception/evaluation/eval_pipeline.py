"""Evaluate the two-stage pipeline on held-out scenes of a generated dataset.

Estimates are matched to ground-truth mushrooms by mask IoU (>= 0.5, greedily by score) against
the visible whole-mushroom masks; masks under ``min_area`` pixels are not counted (as in
``detector_eval``). Matched mushrooms get the stem-axis error (angle between the estimated and
true stem axes), the geodesic error of the full rotation, and the error of the estimated cap top
(the point a picker aims at) in millimetres, in all and across the true stem axis; the angles
are broken down by cap size, tilt and occlusion (the cap's visible fraction from the COCO
annotations). Each mean comes with a 95 % interval that resamples whole scenes
(``scene_bootstrap``): one bed's mushrooms share its soil and noise, so scenes, not mushrooms,
are the independent draws. Reports of several datasets pool with ``PipelineReport.pooled``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from generator.dataset.readers import SceneSample, read_scene_files, scene_indices
from generator.dataset.writer import scene_dirname
from generator.geometry import tilt_angle
from perception.detection.detector import detections_from_labels, mask_iou
from perception.detection.detector_data import first_n
from perception.evaluation.scene_bootstrap import scene_bootstrap_interval
from perception.pipeline import MushroomEstimate, PosePipeline

SIZE_BINS_MM = (0.0, 35.0, 50.0, 65.0, 200.0)
TILT_BINS_DEG = (0.0, 10.0, 20.0, 30.0, 90.0)
VISIBLE_BINS = (0.0, 0.5, 0.8, 0.95, 1.01)
#: Per-mushroom errors of a matched estimate, with their labels in the Markdown report.
ERROR_KEYS = {
    "axis_error_deg": "axis error (°)",
    "geodesic_error_deg": "geodesic error (°)",
    "cap_top_error_mm": "cap top position (mm)",
    "cap_top_lateral_error_mm": "cap top across the stem axis (mm)",
}


@dataclass(frozen=True)
class GroundTruthMushroom:
    scene_id: int
    instance_id: int
    mask: np.ndarray
    rotation: np.ndarray
    cap_top: np.ndarray  # world frame, metres
    cap_diameter_mm: float
    tilt_deg: float
    visible_fraction: float


@dataclass
class PipelineReport:
    """Per-mushroom rows (``matched``: ground truth with its errors, or NaN errors when missed;
    ``dataset`` and ``scene_id`` name its scene)."""

    scenes: int = 0
    estimates: int = 0
    seconds: float = 0.0
    rows: list[dict[str, Any]] = field(default_factory=list)

    @property
    def ground_truth(self) -> int:
        return len(self.rows)

    @property
    def matched(self) -> int:
        return sum(r["matched"] for r in self.rows)

    @property
    def recall(self) -> float:
        return self.matched / self.ground_truth if self.rows else 0.0

    @property
    def precision(self) -> float:
        return self.matched / self.estimates if self.estimates else 0.0

    @classmethod
    def pooled(cls, reports: list[PipelineReport]) -> PipelineReport:
        """One report over the scenes of several (e.g. one per dataset)."""
        return cls(sum(r.scenes for r in reports), sum(r.estimates for r in reports), sum(r.seconds for r in reports),
                   [row for r in reports for row in r.rows])

    def errors(self, key: str) -> np.ndarray:
        return np.array([r[key] for r in self.rows if r["matched"]])

    def error_stats(self, key: str) -> dict[str, Any]:
        """Mean, its 95 % scene-bootstrap interval (``None`` with one scene), median and 90th
        percentile of the matched mushrooms' ``key``; empty without matches."""
        values = self.errors(key)
        if not values.size:
            return {}
        scenes = np.array([f"{r.get('dataset', '')}/{r['scene_id']}" for r in self.rows if r["matched"]])
        interval = scene_bootstrap_interval(values, scenes)
        return {"mean": float(values.mean()), "mean_ci95": None if interval is None else list(interval),
                "median": float(np.median(values)), "p90": float(np.percentile(values, 90))}

    def summary(self) -> dict[str, Any]:
        return {"scenes": self.scenes, "ground_truth": self.ground_truth, "estimates": self.estimates,
                "matched": self.matched, "recall": self.recall, "precision": self.precision,
                **{key: self.error_stats(key) for key in ERROR_KEYS},
                "seconds_per_scene": self.seconds / max(self.scenes, 1),
                "by_cap_diameter_mm": self.breakdown("cap_diameter_mm", SIZE_BINS_MM),
                "by_tilt_deg": self.breakdown("tilt_deg", TILT_BINS_DEG),
                "by_visible_fraction": self.breakdown("visible_fraction", VISIBLE_BINS)}

    def breakdown(self, key: str, edges: tuple[float, ...]) -> list[dict[str, Any]]:
        """Recall and mean errors per bin of ``key`` (a ground-truth property)."""
        out = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            rows = [r for r in self.rows if lo <= r[key] < hi]
            hit = [r for r in rows if r["matched"]]
            out.append({"bin": [lo, hi], "n": len(rows), "recall": len(hit) / len(rows) if rows else None,
                        "mean_axis_error_deg": float(np.mean([r["axis_error_deg"] for r in hit])) if hit else None,
                        "mean_geodesic_error_deg": float(np.mean([r["geodesic_error_deg"] for r in hit])) if hit else None})
        return out

    def markdown(self) -> str:
        s = self.summary()
        lines = [f"{s['scenes']} scenes, {s['ground_truth']} mushrooms, {s['estimates']} estimates: "
                 f"recall {s['recall']:.3f}, precision {s['precision']:.3f}, "
                 f"{s['seconds_per_scene']:.2f} s per scene", ""]
        if s["axis_error_deg"]:
            lines += ["| error of matched mushrooms | mean | mean's 95 % interval (scenes resampled) | median | 90th pct |",
                      "|---|---:|---:|---:|---:|"]
            for name, label in ERROR_KEYS.items():
                e = s[name]
                interval = "–" if e["mean_ci95"] is None else f"{e['mean_ci95'][0]:.2f}–{e['mean_ci95'][1]:.2f}"
                lines.append(f"| {label} | {e['mean']:.2f} | {interval} | {e['median']:.1f} | {e['p90']:.1f} |")
        for title, key in (("cap diameter (mm)", "by_cap_diameter_mm"), ("tilt (°)", "by_tilt_deg"),
                           ("visible cap fraction", "by_visible_fraction")):
            lines += ["", f"| {title} | n | recall | mean axis ° | mean geodesic ° |", "|---|---:|---:|---:|---:|"]
            for b in s[key]:
                fmt = lambda v: "–" if v is None else f"{v:.1f}"  # noqa: E731
                rec = "–" if b["recall"] is None else f"{b['recall']:.2f}"
                lines.append(f"| {b['bin'][0]:g}–{b['bin'][1]:g} | {b['n']} | {rec} | "
                             f"{fmt(b['mean_axis_error_deg'])} | {fmt(b['mean_geodesic_error_deg'])} |")
        return "\n".join(lines) + "\n"


def ground_truth(sample: SceneSample, min_area: int = 16) -> list[GroundTruthMushroom]:
    """The scene's mushrooms with at least ``min_area`` visible pixels."""
    visible = {a["instance_id"]: a.get("visible_fraction", 0.0) for a in sample.annotations if a["category_id"] == 2}
    out = []
    for inst in sample.record["instances"]:
        mask = sample.labels_mushroom == inst["id"] + 1
        if mask.sum() < min_area:
            continue
        rot = np.asarray(inst["rotation"], dtype=float)
        out.append(GroundTruthMushroom(sample.index, inst["id"], mask, rot, np.asarray(inst["cap_top"], dtype=float),
                                       1000.0 * inst["cap_diameter"],
                                       float(np.degrees(tilt_angle(rot))), float(visible.get(inst["id"], 0.0))))
    return out


def _angle_deg(cos: float) -> float:
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def match(estimates: list[MushroomEstimate], truth: list[GroundTruthMushroom], min_iou: float = 0.5) -> list[dict[str, Any]]:
    """One row per ground-truth mushroom: matched (IoU >= ``min_iou``) with its errors, or missed."""
    rows = [{"scene_id": g.scene_id, "instance_id": g.instance_id, "cap_diameter_mm": g.cap_diameter_mm,
             "tilt_deg": g.tilt_deg, "visible_fraction": g.visible_fraction, "matched": False,
             "iou": 0.0, **dict.fromkeys(ERROR_KEYS, float("nan"))} for g in truth]
    taken = np.zeros(len(truth), bool)
    for est in sorted(estimates, key=lambda e: -e.detection.score):
        m = est.detection.mask
        ious = np.array([0.0 if taken[j] else mask_iou(m, g.mask) for j, g in enumerate(truth)])
        if not truth or ious.max() < min_iou:
            continue
        j = int(ious.argmax())
        taken[j] = True
        g = truth[j]
        offset = est.cap_top_world - g.cap_top
        axis = g.rotation[:, 2]
        rows[j].update(matched=True, iou=float(ious[j]),
                       cap_top_error_mm=1000.0 * float(np.linalg.norm(offset)),
                       cap_top_lateral_error_mm=1000.0 * float(np.linalg.norm(offset - (offset @ axis) * axis)),
                       axis_error_deg=_angle_deg(est.stem_axis_world @ g.rotation[:, 2]),
                       geodesic_error_deg=_angle_deg((np.trace(g.rotation.T @ est.rotation_world) - 1.0) / 2.0))
    return rows


def run_scene(pipeline: PosePipeline, sample: SceneSample, oracle: bool) -> list[MushroomEstimate]:
    detections = detections_from_labels(sample.labels_mushroom) if oracle else None
    return pipeline(sample.rgb, sample.depth, sample.intrinsics, sample.world_from_camera, detections)


def evaluate_pipeline(pipeline: PosePipeline, root: str | Path, split: str = "test", oracle: bool = False,
                      min_area: int = 16, max_scenes: int | None = None, progress: bool = False) -> PipelineReport:
    """Run ``pipeline`` (its detector, or oracle masks) on the first ``max_scenes`` scenes of
    ``split`` (all of them for ``None``) and match."""
    indices = first_n(scene_indices(Path(root), split), max_scenes, "max_scenes")
    if progress:
        from tqdm import tqdm
        indices = tqdm(indices, desc=f"eval-pipeline {split}", unit="scene")
    report = PipelineReport()
    for index in indices:
        sample = read_scene_files(Path(root) / scene_dirname(index))
        start = time.perf_counter()
        estimates = run_scene(pipeline, sample, oracle)
        report.seconds += time.perf_counter() - start
        report.scenes += 1
        report.estimates += len(estimates)
        report.rows += [{"dataset": str(root), **row} for row in match(estimates, ground_truth(sample, min_area))]
    return report
