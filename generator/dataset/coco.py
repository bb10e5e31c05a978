"""COCO instance segmentation: RLE-encoded masks per scene, merged into one file per split.

Categories: 1 ``mushroom`` (visible whole mushroom) and 2 ``mushroom_cap`` (visible cap). Every
annotation carries ``scene_id`` and ``instance_id`` (the ``id`` of the instance in that scene's
``scene.json``) and ``species``; cap annotations also carry the amodal cap mask
(``amodal_segmentation``, ``amodal_area``) and ``visible_fraction`` = visible / amodal cap area.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pycocotools import mask as mask_utils

CATEGORIES = [
    {"id": 1, "name": "mushroom", "supercategory": "mushroom"},
    {"id": 2, "name": "mushroom_cap", "supercategory": "mushroom"},
]


def _rle(starts: np.ndarray, ends: np.ndarray, shape: tuple[int, int]) -> dict[str, Any]:
    """Compressed COCO RLE of the mask whose pixels, in column-major order, are the runs
    ``[starts[i], ends[i])`` (sorted, non-adjacent): zeros first, then alternating runs."""
    h, w = shape
    counts = np.empty(2 * len(starts) + 1, dtype=np.int64)
    counts[0:-1:2] = starts - np.concatenate(([0], ends[:-1]))
    counts[1::2] = ends - starts
    counts[-1] = h * w - (ends[-1] if len(ends) else 0)
    if len(ends) and counts[-1] == 0:  # a mask ending in a run of ones has no final zero run
        counts = counts[:-1]
    rle = mask_utils.frPyObjects({"size": [h, w], "counts": counts.tolist()}, h, w)
    return {"size": [h, w], "counts": rle["counts"].decode("ascii")}


def _runs(values: np.ndarray, offset: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Maximal runs of equal values of a 1-D array: start, end (exclusive, plus ``offset``) and value."""
    change = np.flatnonzero(values[1:] != values[:-1]) + 1
    starts = np.concatenate(([0], change))
    ends = np.concatenate((change, [len(values)]))
    return starts + offset, ends + offset, values[starts]


def encode_mask(mask: np.ndarray) -> dict[str, Any]:
    """COCO RLE of a boolean mask, with ``counts`` as text (JSON-ready); the same string as
    ``pycocotools.mask.encode``, from the columns the mask occupies only."""
    mask = np.asarray(mask, dtype=bool)
    h = mask.shape[0]
    columns = np.flatnonzero(mask.any(axis=0))
    if len(columns) == 0:
        return _rle(np.zeros(0, np.int64), np.zeros(0, np.int64), mask.shape)
    c0, c1 = int(columns[0]), int(columns[-1]) + 1
    starts, ends, values = _runs(mask[:, c0:c1].T.ravel(), c0 * h)  # column-major, as COCO counts
    return _rle(starts[values], ends[values], mask.shape)


def encode_labels(labels: np.ndarray) -> dict[int, dict[str, Any]]:
    """COCO RLE of ``labels == k`` for every non-zero label ``k`` of a label image, in one pass."""
    starts, ends, values = _runs(labels.T.ravel(), 0)
    keep = values != 0
    starts, ends, values = starts[keep], ends[keep], values[keep]
    order = np.argsort(values, kind="stable")  # stable: each label's runs stay in pixel order
    starts, ends, values = starts[order], ends[order], values[order]
    labels_present, first = np.unique(values, return_index=True)
    bounds = np.append(first, len(values))
    return {int(k): _rle(starts[a:b], ends[a:b], labels.shape)
            for k, a, b in zip(labels_present, bounds[:-1], bounds[1:])}


def decode_mask(rle: dict[str, Any]) -> np.ndarray:
    """Boolean mask of a COCO RLE whose ``counts`` is text (as written here) or bytes."""
    counts = rle["counts"]
    return mask_utils.decode({"size": rle["size"], "counts": counts.encode("ascii") if isinstance(counts, str) else counts}).astype(bool)


def rle_area_bbox(rle: dict[str, Any]) -> tuple[int, list[float]]:
    coded = {"size": rle["size"], "counts": rle["counts"].encode("ascii")}
    return int(mask_utils.area(coded)), [float(x) for x in mask_utils.toBbox(coded)]


def scene_annotations(labels_mushroom: np.ndarray, labels_cap: np.ndarray,
                      amodal_caps: dict[int, dict[str, Any]], instances: list[Any]) -> list[dict[str, Any]]:
    """Per-scene annotations without image or annotation ids (added when merging);
    ``amodal_caps`` maps instance ids to the RLEs of their amodal cap masks."""
    anns: list[dict[str, Any]] = []
    visible = {1: encode_labels(labels_mushroom), 2: encode_labels(labels_cap)}
    for inst in instances:
        label = inst.id + 1
        for category in (1, 2):
            rle = visible[category].get(label)
            if rle is None:
                continue
            area, bbox = rle_area_bbox(rle)
            ann: dict[str, Any] = {"category_id": category, "instance_id": inst.id, "species": inst.species,
                                   "segmentation": rle, "area": area, "bbox": bbox, "iscrowd": 0}
            if category == 2 and inst.id in amodal_caps:
                amodal = amodal_caps[inst.id]
                amodal_area, amodal_bbox = rle_area_bbox(amodal)
                ann.update(amodal_segmentation=amodal, amodal_area=amodal_area, amodal_bbox=amodal_bbox,
                           visible_fraction=area / amodal_area if amodal_area else 0.0)
            anns.append(ann)
    return anns


def merge_split(scenes: list[tuple[int, dict[str, Any], list[dict[str, Any]]]], split: str) -> dict[str, Any]:
    """One COCO dict from ``(scene index, image entry, annotations)`` in scene order."""
    images, annotations = [], []
    next_id = 1
    for index, image, anns in scenes:
        images.append({**image, "id": index, "scene_id": index})
        for ann in anns:
            annotations.append({**ann, "id": next_id, "image_id": index, "scene_id": index})
            next_id += 1
    return {"info": {"description": f"SMS3D-pick synthetic mushroom beds, {split} split", "version": "1"},
            "licenses": [], "categories": CATEGORIES, "images": images, "annotations": annotations}
