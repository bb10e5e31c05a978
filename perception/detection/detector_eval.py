"""Detector evaluation on a COCO split: COCO AP/AR (pycocotools) and F1 for boxes and masks.

F1 is the paper's Table 5 measure: detections scoring at least the detector's
``score_threshold`` are matched greedily by score to ground truth at IoU >= 0.5; precision =
TP / detections, recall = TP / ground truth. Ground-truth masks smaller than ``min_area`` pixels
(slivers of nearly hidden mushrooms) are marked ``iscrowd`` so that neither measure counts them
as missed nor a detection on them as false.
"""

from __future__ import annotations

import contextlib
import copy
import io
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from perception.choices import CATEGORIES
from perception.detection.detector import Detection, Detector
from perception.detection.detector_data import CocoDetectionDataset, first_n


@dataclass(frozen=True)
class DetectionScores:
    """COCO AP (IoU .50:.95), AP50, AP75, AR (100 detections) and F1 at IoU 0.5."""

    ap: float
    ap50: float
    ap75: float
    ar: float
    precision: float
    recall: float
    f1: float


@dataclass(frozen=True)
class DetectorReport:
    images: int
    ground_truth: int
    detections: int
    box: DetectionScores
    mask: DetectionScores
    ms_per_image: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def markdown(self) -> str:
        rows = ["| | AP | AP50 | AP75 | AR | precision | recall | F1 |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
        for name, s in (("box", self.box), ("mask", self.mask)):
            rows.append(f"| {name} | {s.ap:.3f} | {s.ap50:.3f} | {s.ap75:.3f} | {s.ar:.3f} | "
                        f"{s.precision:.3f} | {s.recall:.3f} | {s.f1:.3f} |")
        return "\n".join(rows) + (f"\n\n{self.images} images, {self.ground_truth} ground-truth instances, "
                                  f"{self.detections} detections, {self.ms_per_image:.0f} ms per image\n")


def _rle(mask: np.ndarray) -> dict[str, Any]:
    return mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))


def _f1(gt: list[dict[str, Any]], dt: list[dict[str, Any]], iou_type: str, score_threshold: float) -> tuple[int, int, int]:
    """(true positives, detections kept, ground truth counted) of one image."""
    kept = sorted((d for d in dt if d["score"] >= score_threshold), key=lambda d: -d["score"])
    counted = [g for g in gt if not g["iscrowd"]]
    crowd = [g for g in gt if g["iscrowd"]]
    key = "segmentation" if iou_type == "segm" else "bbox"
    if not kept:
        return 0, 0, len(counted)
    if counted:
        iou = np.atleast_2d(mask_utils.iou([d[key] for d in kept], [g[key] for g in counted], [0] * len(counted)))
    else:
        iou = np.zeros((len(kept), 0))
    matched = np.zeros(len(counted), bool)
    tp = false_pos = 0
    for i in range(len(kept)):
        candidates = np.where(~matched & (iou[i] >= 0.5))[0] if counted else []
        if len(candidates):
            matched[candidates[np.argmax(iou[i, candidates])]] = True
            tp += 1
        elif crowd and np.max(mask_utils.iou([kept[i][key]], [g[key] for g in crowd], [1] * len(crowd))) >= 0.5:
            continue  # on an ignored sliver: neither right nor wrong
        else:
            false_pos += 1
    return tp, tp + false_pos, len(counted)


def _scores(coco_gt: COCO, results: list[dict[str, Any]], iou_type: str, category_id: int,
            per_image_gt: dict[int, list], score_threshold: float) -> DetectionScores:
    stats = np.zeros(12)
    if results:
        with contextlib.redirect_stdout(io.StringIO()):  # pycocotools prints its tables
            coco_dt = coco_gt.loadRes(copy.deepcopy(results))
            ev = COCOeval(coco_gt, coco_dt, iou_type)
            ev.params.catIds = [category_id]
            ev.evaluate()
            ev.accumulate()
            ev.summarize()
        stats = np.maximum(ev.stats, 0.0)  # -1 = no ground truth: report 0
    by_image: dict[int, list] = {}
    for r in results:
        by_image.setdefault(r["image_id"], []).append(r)
    tp = kept = counted = 0
    for image_id, gts in per_image_gt.items():
        a, b, c = _f1(gts, by_image.get(image_id, []), iou_type, score_threshold)
        tp, kept, counted = tp + a, kept + b, counted + c
    precision = tp / kept if kept else 0.0
    recall = tp / counted if counted else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return DetectionScores(float(stats[0]), float(stats[1]), float(stats[2]), float(stats[8]), precision, recall, f1)


def evaluate_detector(detector: Detector, root: str | Path, split: str = "test", category: str = "mushroom",
                      min_area: int = 16, score_threshold: float = 0.5, max_images: int | None = None,
                      progress: bool = False) -> DetectorReport:
    """Run ``detector`` on every image of ``split`` and score it against the COCO ground truth.

    All detections enter COCO AP/AR (which sweeps the score); F1 uses those scoring at least
    ``score_threshold``.
    """
    data = CocoDetectionDataset(root, split, category, min_area=0)
    category_id = CATEGORIES[category]
    images = first_n(data.images, max_images, "max_images")
    image_ids = {im["id"] for im in images}
    gt = copy.deepcopy(data.coco)
    gt["images"] = images
    gt["annotations"] = [dict(a, iscrowd=int(a["area"] < min_area)) for a in gt["annotations"]
                         if a["category_id"] == category_id and a["image_id"] in image_ids]
    for a in gt["annotations"]:  # pycocotools wants byte counts for the IoU calls below
        if isinstance(a["segmentation"]["counts"], str):
            a["segmentation"] = {"size": a["segmentation"]["size"], "counts": a["segmentation"]["counts"].encode("ascii")}
    coco_gt = COCO()
    coco_gt.dataset = gt
    with contextlib.redirect_stdout(io.StringIO()):
        coco_gt.createIndex()
    per_image_gt: dict[int, list] = {im["id"]: [] for im in images}
    for a in gt["annotations"]:
        per_image_gt[a["image_id"]].append(a)

    box_results, mask_results = [], []
    elapsed = 0.0
    iterator = range(len(images))
    if progress:
        from tqdm import tqdm
        iterator = tqdm(iterator, desc=f"eval-detector {split}", unit="image")
    for i in iterator:
        rgb, depth = data.image_rgb(i), data.image_depth(i)
        start = time.perf_counter()
        detections: list[Detection] = detector.detect(rgb, depth)
        elapsed += time.perf_counter() - start
        for det in detections:
            x0, y0, x1, y1 = det.box
            common = {"image_id": images[i]["id"], "category_id": category_id, "score": float(det.score)}
            box_results.append({**common, "bbox": [float(x0), float(y0), float(x1 - x0 + 1), float(y1 - y0 + 1)]})
            mask_results.append({**common, "segmentation": _rle(det.mask)})
    counted = sum(1 for a in gt["annotations"] if not a["iscrowd"])
    return DetectorReport(
        images=len(images), ground_truth=counted, detections=len(box_results),
        box=_scores(coco_gt, box_results, "bbox", category_id, per_image_gt, score_threshold),
        mask=_scores(coco_gt, mask_results, "segm", category_id, per_image_gt, score_threshold),
        ms_per_image=1000.0 * elapsed / max(len(images), 1),
    )
