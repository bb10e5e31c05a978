"""Draw a scene's instance masks (coloured overlay) and projected 3D cap boxes on its RGB image."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from generator.camera import project
from generator.dataset.errors import DatasetWriteError
from generator.dataset.readers import read_scene_files
from generator.dataset.writer import scene_dirname
from generator.geometry import OrientedBox

# Box corners are ordered x slowest, z fastest: an edge joins corners differing in one bit.
BOX_EDGES = [(a, a | bit) for a in range(8) for bit in (1, 2, 4) if not a & bit]


def palette(n: int) -> np.ndarray:
    """Distinct, fixed colours (uint8 RGB) for labels 0..n-1 (0 is black)."""
    hues = (np.arange(n) * 0.618034 % 1.0 * 180).astype(np.uint8)
    hsv = np.stack([hues, np.full(n, 200, np.uint8), np.full(n, 255, np.uint8)], 1)[None]
    colours = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0]
    colours[0] = 0
    return colours


def overlay(root: str | Path, index: int, labels: str = "mushroom", alpha: float = 0.45) -> np.ndarray:
    """The overlay image (RGB uint8) of scene ``index``."""
    s = read_scene_files(Path(root) / scene_dirname(index))
    if labels == "amodal":
        lab = np.zeros(s.labels_cap.shape, np.int64)
        for iid, m in s.amodal_caps.items():
            lab[m & (lab == 0)] = iid + 1
    else:
        lab = (s.labels_cap if labels == "cap" else s.labels_mushroom).astype(np.int64)
    colours = palette(int(lab.max()) + 1)
    img = s.rgb.astype(np.float32)
    fg = lab > 0
    img[fg] = (1 - alpha) * img[fg] + alpha * colours[lab[fg]]
    img = img.astype(np.uint8)
    intr = s.intrinsics
    pose = s.world_from_camera
    for inst in s.record["instances"]:
        box = OrientedBox.from_dict(inst["cap_obb"])
        uvz = project(box.corners, pose, intr)
        if np.any(uvz[:, 2] <= 0):
            continue
        colour = tuple(int(c) for c in colours[(inst["id"] + 1) % len(colours)]) if labels != "amodal" else (255, 255, 0)
        pts = np.rint(uvz[:, :2]).astype(int)
        for a, b in BOX_EDGES:
            cv2.line(img, tuple(map(int, pts[a])), tuple(map(int, pts[b])), colour, 1, cv2.LINE_AA)
    return img


#: What the overlay's colours and lines mean, per ``labels`` (its title bar is its legend).
OVERLAY_LEGENDS = {
    "mushroom": "a colour per mushroom's visible mask, lines: its cap's 3-D box",
    "cap": "a colour per visible cap mask, lines: the cap's 3-D box",
    "amodal": "a colour per cap's whole (amodal) mask, yellow lines: its 3-D box",
}


def render_overlay(root: str | Path, index: int, out_png: str | Path, labels: str = "mushroom") -> Path:
    """Write the overlay of scene ``index`` to ``out_png``, under a title bar that names the
    scene and says what the colours and lines show."""
    from generator.image_text import with_title

    img = with_title(overlay(root, index, labels), f"Scene {index}: {OVERLAY_LEGENDS[labels]}")
    out_png = Path(out_png)
    ok, buf = cv2.imencode(".png", cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    try:
        out_png.write_bytes(buf.tobytes())
    except OSError as exc:
        raise DatasetWriteError(out_png, f"cannot write ({exc.strerror or exc})") from exc
    return out_png
