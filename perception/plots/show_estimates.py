"""A picture of a scene's estimates: predicted and ground-truth cap boxes over the RGB image (as
in the SMS3D paper's Figure 11), and the same boxes in 3D over the scene's points from a second
viewpoint.

Ground truth boxes are the annotated cap boxes. A predicted box is built from the estimate alone:
its axes are the estimated rotation, its top the estimated cap top, its width the spread of the
mushroom's observed points across the estimated stem axis and its height half that width (the
cap proportions of the generator's models).
"""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from generator.camera import project
from generator.dataset.readers import SceneSample
from generator.dataset.show import BOX_EDGES
from generator.files import write_atomic
from generator.geometry import OrientedBox
from perception.pipeline import MushroomEstimate
from perception.pointcloud import depth_to_points

TRUTH_RGB = (60, 220, 60)
ESTIMATE_RGB = (255, 60, 40)


def estimate_box(estimate: MushroomEstimate, points_world: np.ndarray) -> OrientedBox:
    """The cap box implied by an estimate and its mushroom's observed world-frame points."""
    rot = estimate.rotation_world
    axis = rot[:, 2]
    rel = points_world - estimate.cap_top_world
    radial = np.linalg.norm(rel - np.outer(rel @ axis, axis), axis=1)
    width = 2.0 * float(np.percentile(radial, 95)) if len(radial) else 0.02
    height = 0.5 * width
    return OrientedBox(estimate.cap_top_world - axis * height / 2.0, np.array([width, width, height]), rot)


def _draw_boxes(img: np.ndarray, boxes: list[OrientedBox], sample: SceneSample, colour: tuple[int, int, int]) -> None:
    intr = sample.intrinsics
    for box in boxes:
        uvz = project(box.corners, sample.world_from_camera, intr)
        if np.any(uvz[:, 2] <= 0):
            continue
        pts = np.rint(uvz[:, :2]).astype(int)
        for a, b in BOX_EDGES:
            cv2.line(img, tuple(map(int, pts[a])), tuple(map(int, pts[b])), colour, 2, cv2.LINE_AA)


def estimates_figure(sample: SceneSample, estimates: list[MushroomEstimate], out_png: str | Path,
                     elevation: float = 30.0, azimuth: float = -65.0,
                     trim_mask: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None) -> Path:
    """Write the two-panel PNG (image overlay | 3D view) of ``estimates`` on ``sample``; boxes are
    sized from the masks trimmed as the pipeline trimmed them (``trim_mask(mask, depth)``, e.g.
    ``PosePipeline.trim_mask``; ``None``: whole masks)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    intr = sample.intrinsics
    world = sample.world_from_camera
    truth = [OrientedBox.from_dict(inst["cap_obb"]) for inst in sample.record["instances"]
             if (sample.labels_mushroom == inst["id"] + 1).any()]
    predicted = []
    for est in estimates:
        mask = est.detection.mask
        if trim_mask is not None:
            mask = trim_mask(mask, sample.depth)
        pts, _ = depth_to_points(sample.depth, intr, mask)
        predicted.append(estimate_box(est, pts @ world[:3, :3].T + world[:3, 3]))

    overlay = sample.rgb.copy()
    for est in estimates:
        overlay[est.detection.mask] = (0.6 * overlay[est.detection.mask] + 0.4 * np.array(ESTIMATE_RGB)).astype(np.uint8)
    _draw_boxes(overlay, truth, sample, TRUTH_RGB)
    _draw_boxes(overlay, predicted, sample, ESTIMATE_RGB)

    points, colours = depth_to_points(sample.depth, intr, sample.depth > 0, sample.rgb)
    points = points @ world[:3, :3].T + world[:3, 3]
    corners = np.concatenate([b.corners for b in truth + predicted]) if truth or predicted else points
    lo, hi = corners.min(0) - 0.02, corners.max(0) + 0.02  # zoom on the mushrooms
    inside = np.all((points >= lo) & (points <= hi), axis=1)
    keep = np.flatnonzero(inside)
    keep = np.random.default_rng(0).choice(keep, size=min(len(keep), 40_000), replace=False)
    points, colours = points[keep], colours[keep]

    fig = plt.figure(figsize=(13, 5.2), dpi=110)
    ax_img = fig.add_subplot(1, 2, 1)
    ax_img.imshow(overlay)
    ax_img.set_title(f"scene {sample.index}: ground truth (green) and estimated (red) cap boxes")
    ax_img.axis("off")
    ax3d = fig.add_subplot(1, 2, 2, projection="3d")
    ax3d.scatter(points[:, 0], points[:, 1], points[:, 2], c=colours,
                 s=0.6, linewidths=0)
    for boxes, colour in ((truth, TRUTH_RGB), (predicted, ESTIMATE_RGB)):
        for box in boxes:
            c = box.corners
            for a, b in BOX_EDGES:
                ax3d.plot(*zip(c[a], c[b]), color=np.array(colour) / 255.0, linewidth=0.8)
    ax3d.view_init(elev=elevation, azim=azimuth)
    ax3d.set_xlim(lo[0], hi[0])
    ax3d.set_ylim(lo[1], hi[1])
    ax3d.set_zlim(lo[2], hi[2])
    ax3d.set_box_aspect(tuple(np.maximum(hi - lo, 0.08)))
    ax3d.set_xlabel("x (m)")
    ax3d.set_ylabel("y (m)")
    ax3d.set_zlabel("z (m)")
    ax3d.set_title("the same boxes in 3D (observed points, second viewpoint)")
    fig.legend(handles=[Line2D([], [], color=np.array(TRUTH_RGB) / 255.0, label="ground-truth cap box"),
                        Line2D([], [], color=np.array(ESTIMATE_RGB) / 255.0, label="estimated cap box"),
                        Patch(facecolor=np.array(ESTIMATE_RGB) / 255.0, alpha=0.4, label="detected mask")],
               loc="lower center", ncol=3, fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    plt.close(fig)
    out_png = Path(out_png)
    write_atomic(out_png, buffer.getvalue())
    return out_png
