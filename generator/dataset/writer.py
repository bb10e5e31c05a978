"""Write one rendered scene atomically: files go to ``scene_XXXXXX.tmp/``, a ``DONE`` file with
their SHA-256 sums is written last, then the folder is renamed to ``scene_XXXXXX/``.

Per scene: ``rgb.png``; ``depth.png`` (uint16 millimetres, 0 = invalid); ``labels_mushroom.png``
and ``labels_cap.png`` (uint16 visible instance labels, 0 background, instance id + 1);
``amodal_caps.json`` (instance id -> COCO RLE of the cap alone); ``annotations.json`` (COCO
annotations of this scene); ``scene.json`` (``Scene.to_dict()`` plus ``camera`` and ``dataset``;
``dataset`` records the run seed and dataset options, so a resumed run can check every scene
against the settings it was asked for, manifest or not).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from generator.dataset.coco import encode_mask, scene_annotations
from generator.dataset.render import Frame
from generator.scene import Scene

DEPTH_SCALE = 0.001  # metres per depth PNG unit
FILES = ("rgb.png", "depth.png", "labels_mushroom.png", "labels_cap.png", "amodal_caps.json",
         "annotations.json", "scene.json")
DONE = "DONE"
# Scene folders are numbered with six digits, so that their names sort in index order.
MAX_SCENES = 1_000_000
SCENE_DIR = re.compile(r"scene_(\d{6})")


def scene_dirname(index: int) -> str:
    return f"scene_{index:06d}"


def dumps(obj: Any) -> str:
    """Deterministic JSON (sorted keys, floats as ``repr``)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def _write_bytes(path: Path, data: bytes) -> None:
    with open(path, "wb") as fh:
        fh.write(data)


# zlib level 1 with run-length matching after the "up" filter: about 3x faster to write than
# level 3 with adaptive filters, and smaller for these images (rendered RGB, depth, labels).
_PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE,
               cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_UP]


def encode_png(image: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", image, _PNG_PARAMS)
    if not ok:
        raise ValueError("PNG encoding failed")
    return buf.tobytes()


def depth_to_png_units(depth_m: np.ndarray) -> np.ndarray:
    mm = np.rint(np.asarray(depth_m, dtype=np.float64) / DEPTH_SCALE)
    return np.where((mm > 0) & (mm <= 65535), mm, 0).astype(np.uint16)


def camera_dict(frame: Frame) -> dict[str, Any]:
    return {
        "convention": "opencv",
        "intrinsics": frame.intrinsics.to_dict(),
        "K": frame.intrinsics.matrix.tolist(),
        "world_from_camera": frame.world_from_camera.tolist(),
        "depth_scale": DEPTH_SCALE,
        "depth_type": "planar_z",
        "znear": frame.znear,
        "zfar": frame.zfar,
    }


def scene_record(scene: Scene, frame: Frame, index: int, split: str, run_seed: int,
                 options: dict[str, Any]) -> dict[str, Any]:
    record = scene.to_dict()
    record["camera"] = camera_dict(frame)
    record["dataset"] = {"index": index, "split": split, "realism": frame.realism, "run_seed": run_seed,
                         "options": options, "label_offset": 1, "files": list(FILES)}
    return record


def write_scene(out_dir: Path, index: int, scene: Scene, frame: Frame, split: str, run_seed: int,
                options: dict[str, Any]) -> Path:
    """Write scene ``index`` of the run ``run_seed`` (made with the dataset ``options``) into
    ``out_dir``; returns the final folder. On any error the temporary folder is removed (if
    possible) and the error propagates."""
    final = out_dir / scene_dirname(index)
    tmp = out_dir / (scene_dirname(index) + ".tmp")
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        tmp.mkdir()
        h, w = frame.depth.shape
        amodal = {k: encode_mask(v) for k, v in frame.amodal_caps.items()}
        contents = {
            "rgb.png": encode_png(cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)),
            "depth.png": encode_png(depth_to_png_units(frame.depth)),
            "labels_mushroom.png": encode_png(frame.labels_mushroom),
            "labels_cap.png": encode_png(frame.labels_cap),
            "amodal_caps.json": dumps({str(k): v for k, v in amodal.items()}).encode(),
            "annotations.json": dumps({
                "image": {"file_name": f"{final.name}/rgb.png", "depth_file": f"{final.name}/depth.png",
                          "width": w, "height": h, "split": split},
                "annotations": scene_annotations(frame.labels_mushroom, frame.labels_cap, amodal, scene.instances),
            }).encode(),
            "scene.json": dumps(scene_record(scene, frame, index, split, run_seed, options)).encode(),
        }
        for name in FILES:
            _write_bytes(tmp / name, contents[name])
        sums = {name: hashlib.sha256(contents[name]).hexdigest() for name in FILES}
        _write_bytes(tmp / DONE, dumps(sums).encode())
        if final.exists():  # a folder without DONE from an older, broken run
            shutil.rmtree(final)
        os.rename(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return final


def is_complete(folder: Path) -> bool:
    return (folder / DONE).is_file()
