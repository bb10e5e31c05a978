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


def encode_mask(mask: np.ndarray) -> dict[str, Any]:
    """COCO RLE of a boolean mask, with ``counts`` as text (JSON-ready)."""
    rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(rle["size"][0]), int(rle["size"][1])], "counts": rle["counts"].decode("ascii")}


def rle_area_bbox(rle: dict[str, Any]) -> tuple[int, list[float]]:
    coded = {"size": rle["size"], "counts": rle["counts"].encode("ascii")}
    return int(mask_utils.area(coded)), [float(x) for x in mask_utils.toBbox(coded)]


def scene_annotations(labels_mushroom: np.ndarray, labels_cap: np.ndarray,
                      amodal_caps: dict[int, np.ndarray], instances: list[Any]) -> list[dict[str, Any]]:
    """Per-scene annotations without image or annotation ids (added when merging)."""
    anns: list[dict[str, Any]] = []
    present = {1: set(np.unique(labels_mushroom).tolist()), 2: set(np.unique(labels_cap).tolist())}
    for inst in instances:
        label = inst.id + 1
        for category, labels in ((1, labels_mushroom), (2, labels_cap)):
            if label not in present[category]:
                continue
            rle = encode_mask(labels == label)
            area, bbox = rle_area_bbox(rle)
            ann: dict[str, Any] = {"category_id": category, "instance_id": inst.id, "species": inst.species,
                                   "segmentation": rle, "area": area, "bbox": bbox, "iscrowd": 0}
            if category == 2 and inst.id in amodal_caps:
                amodal = encode_mask(amodal_caps[inst.id])
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
