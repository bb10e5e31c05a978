"""A picture of what stage 1 and stage 2 saw: each detection's mask tinted over the RGB image and
outlined, each estimate's stem axis drawn from its cap top (camera-frame estimates projected with
the camera matrix ``K``) and, where the ground truth is known, each mushroom's true axis beside it
in a second colour; ``save_masks_and_axes_figure`` adds the title and the legend."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from generator.files import write_atomic
from perception.pipeline import MushroomEstimate

#: Length of the drawn stem axis, metres (about a cap's diameter).
AXIS_LENGTH_M = 0.04
#: Colours (RGB) of the masks and of the two kinds of axis: a pair that colour-blind readers
#: tell apart too (yellow and blue, from Okabe and Ito's palette).
MASK_RGB = (255, 255, 255)
ESTIMATE_RGB = (240, 228, 66)
TRUTH_RGB = (0, 114, 178)


def _arrow(image: np.ndarray, cap_top: np.ndarray, axis: np.ndarray, K: np.ndarray,
           colour: tuple[int, int, int], width: int) -> None:
    """Draw ``AXIS_LENGTH_M`` of a stem axis (camera frame, metres) into ``image``, the arrow
    pointing up the stem to ``cap_top``, ``width`` pixels of ``colour`` on a black outline;
    nothing behind the camera."""
    pts = []
    for p in (cap_top - AXIS_LENGTH_M * axis, cap_top):
        if p[2] <= 0:
            return
        uvw = K @ p
        pts.append((int(round(uvw[0] / uvw[2])), int(round(uvw[1] / uvw[2]))))
    cv2.arrowedLine(image, pts[0], pts[1], (0, 0, 0), width + 2, cv2.LINE_AA, tipLength=0.3)
    cv2.arrowedLine(image, pts[0], pts[1], colour, width, cv2.LINE_AA, tipLength=0.3)


def draw_masks_and_axes(rgb: np.ndarray, estimates: list[MushroomEstimate], K: np.ndarray,
                        alpha: float = 0.35,
                        truth: Sequence[tuple[np.ndarray, np.ndarray]] = ()) -> np.ndarray:
    """``(H, W, 3)`` uint8: ``rgb`` with every estimate's mask tinted (``alpha``) and outlined in
    ``MASK_RGB``, its stem axis in ``ESTIMATE_RGB`` and each ``truth`` pair (true cap top,
    true stem axis; camera frame, metres) in ``TRUTH_RGB``: arrows ``AXIS_LENGTH_M`` long,
    up the stem to the cap top. The true axes are drawn first and wider: an estimate that matches
    its truth runs inside a band of the truth's colour, one that misses beside it."""
    out = rgb.astype(np.float32).copy()
    K = np.asarray(K, dtype=float)
    for est in estimates:
        mask = est.detection.mask
        out[mask] = (1 - alpha) * out[mask] + alpha * np.array(MASK_RGB, np.float32)
    out = out.clip(0, 255).astype(np.uint8)
    for est in estimates:
        contours, _ = cv2.findContours(est.detection.mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(out, contours, -1, MASK_RGB, 1, cv2.LINE_AA)
    for cap_top, axis in truth:
        _arrow(out, np.asarray(cap_top, float), np.asarray(axis, float), K, TRUTH_RGB, 6)
    for est in estimates:
        _arrow(out, est.cap_top_cam, est.stem_axis_cam, K, ESTIMATE_RGB, 2)
    return out


def save_masks_and_axes_figure(image: np.ndarray, path: str | Path, title: str,
                               estimate_label: str = "estimated stem axis",
                               truth_label: str | None = "true stem axis",
                               mask_label: str = "detected mask") -> None:
    """Write ``image`` (a ``draw_masks_and_axes`` picture) as a PNG figure, atomically, under
    ``title`` with a legend naming its colours (``truth_label`` None: no truth was drawn)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    h, w = image.shape[:2]
    fig, ax = plt.subplots(figsize=(w / 100 + 0.4, h / 100 + 1.2), dpi=100)
    ax.imshow(image)
    ax.set_axis_off()
    ax.set_title(f"{title}\narrows: {1000 * AXIS_LENGTH_M:.0f} mm of stem axis, head at the cap top",
                 fontsize=10)
    handles = [Patch(facecolor=np.array(MASK_RGB) / 255, edgecolor="k", label=mask_label),
               Line2D([], [], color=np.array(ESTIMATE_RGB) / 255, lw=2.5, label=estimate_label)]
    if truth_label is not None:
        handles.append(Line2D([], [], color=np.array(TRUTH_RGB) / 255, lw=5, label=truth_label))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    plt.close(fig)
    write_atomic(Path(path), buffer.getvalue())
