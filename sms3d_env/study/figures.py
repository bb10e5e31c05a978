"""Figure helpers shared by the study and training: atomic PNG saves, checks of a figure's path
before the work, distinct labels for folders, and success-vs-error curves with their intervals.

Matplotlib loads inside the functions (importing this module costs nothing); this module imports
no other module of the study or of training.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from generator.files import write_atomic

ORIENTATION_LABEL = "orientation error θ (degrees, rotation perpendicular to the stem)"


def save_figure(fig: Any, path: str | Path) -> None:
    """Write a matplotlib figure as PNG atomically and close it."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120)
    plt.close(fig)
    write_atomic(Path(path), buffer.getvalue())


def check_figure_path(out: str | Path, flag: str = "--out") -> None:
    """``ValueError`` naming ``flag`` unless ``out`` can be a figure's path: not empty, no folder,
    in a folder that exists (checked before the work, which would otherwise be lost at the end)."""
    path = Path(out)
    if not str(out).strip():
        raise ValueError(f"{flag} must name a PNG file, got an empty path")
    if path.is_dir():
        raise ValueError(f"{flag} {out}: is a folder; name the PNG file to write")
    if not path.absolute().parent.is_dir():
        raise ValueError(f"{flag} {out}: the folder {path.absolute().parent} does not exist")


def distinct_names(paths: Sequence[str | Path]) -> list[str]:
    """A label per folder: the shortest suffix of its path that no other folder's path ends with
    (``a/seed0`` and ``b/seed0`` for two runs named ``seed0``); ``ValueError`` naming a folder
    given twice."""
    parts = [Path(p).resolve().parts for p in paths]
    for i, mine in enumerate(parts):
        if mine in parts[:i]:
            raise ValueError(f"{paths[i]} is given twice")
    names = []
    for mine in parts:
        depth = next(k for k in range(1, len(mine) + 1)
                     if all(other[-k:] != mine[-k:] for other in parts if other != mine))
        names.append(str(Path(*mine[-depth:])))
    return names


def draw_curve(ax: Any, table: Sequence[dict[str, Any]], label: str, **style: Any) -> None:
    """One success-vs-error line of a ``success_table`` on ``ax``: percent with its 95 % Wilson
    interval as error bars, ``n`` per error in the label; ``style`` goes to ``errorbar``."""
    y = [100 * t["success"] for t in table]
    err = [[100 * (t["success"] - t["ci_low"]) for t in table], [100 * (t["ci_high"] - t["success"]) for t in table]]
    ax.errorbar([t["error_deg"] for t in table], y, yerr=err, capsize=3,
                label=f"{label} (n = {min(t['n'] for t in table)}/error)", **{"marker": "o", **style})


def success_axes(ax: Any, xlabel: str = ORIENTATION_LABEL) -> None:
    """Label ``ax`` as pick success (%) against ``xlabel``, 0–105 %, with a light grid."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel("pick success (%)")
    ax.set_ylim(0, 105)
    ax.grid(alpha=0.3)


def plot_curves(curves: dict[str, Sequence[dict[str, Any]]], path: str | Path, title: str,
                xlabel: str = ORIENTATION_LABEL) -> None:
    """Success vs orientation error with 95 % Wilson intervals, one line per label; each value
    is a ``success_table`` of one slice."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, table in curves.items():
        draw_curve(ax, table, label)
    success_axes(ax, xlabel)
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title(title)
    fig.tight_layout()
    save_figure(fig, path)


def polyline_points(xy: Any, step_px: float = 2.0) -> Any:
    """Display points every ``step_px`` along a polyline of display coordinates (N, 2)."""
    import numpy as np

    xy = np.asarray(xy, float).reshape(-1, 2)
    xy = xy[np.isfinite(xy).all(axis=1)]
    if len(xy) < 2:
        return xy
    out = [xy[:1]]
    for a, b in zip(xy[:-1], xy[1:]):
        k = max(1, int(np.ceil(np.hypot(*(b - a)) / step_px)))
        out.append(a + (b - a) * np.linspace(0.0, 1.0, k + 1)[1:, None])
    return np.concatenate(out)


def drawn_points(ax: Any, skip: Sequence[Any] = ()) -> Any:
    """Display points along every line of ``ax`` (curves, error bars, vertical marks, contour
    lines) and at every scatter marker, except the artists in ``skip``: what a label must clear."""
    import numpy as np
    from matplotlib.collections import LineCollection, PathCollection

    points = [np.zeros((0, 2))]
    for line in ax.get_lines():
        if line not in skip and line.get_visible() and line.get_linestyle() not in ("None", "", " "):
            points.append(polyline_points(line.get_transform().transform(line.get_xydata())))
        elif line not in skip and line.get_visible():  # markers only (error-bar caps)
            points.append(line.get_transform().transform(line.get_xydata()))
    for coll in ax.collections:
        if coll in skip or not coll.get_visible():
            continue
        if isinstance(coll, PathCollection):  # scatter markers
            points.append(coll.get_offset_transform().transform(coll.get_offsets()))
        elif isinstance(coll, LineCollection) or hasattr(coll, "get_paths"):
            for path in coll.get_paths():
                for poly in path.to_polygons(closed_only=False):
                    points.append(polyline_points(coll.get_transform().transform(poly)))
    return np.concatenate(points)


def boxes_overlap(a: Any, b: Any, pad_px: float = 0.0) -> bool:
    return a.x0 - pad_px < b.x1 and b.x0 - pad_px < a.x1 and a.y0 - pad_px < b.y1 and b.y0 - pad_px < a.y1


def points_in_box(points: Any, box: Any, pad_px: float = 0.0) -> int:
    x, y = points[:, 0], points[:, 1]
    return int(((x > box.x0 - pad_px) & (x < box.x1 + pad_px) & (y > box.y0 - pad_px) & (y < box.y1 + pad_px)).sum())


def place_clear(ax: Any, candidates: Sequence[dict[str, Any]], boxes: Sequence[Any], points: Any,
                pad_px: float = 2.0) -> Any:
    """Annotate ``ax`` at the first of ``candidates`` (``ax.annotate`` keyword arguments) whose
    text lies inside the axes and clears the ``boxes`` (display bounding boxes) and ``points``
    (display points, ``drawn_points``) by ``pad_px``; when none does, at the one that covers the
    fewest. Returns the text. Call it once the figure's layout is final (after ``tight_layout``)."""
    renderer = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    best, best_cost = None, None
    for kwargs in candidates:
        text = ax.annotate(**kwargs)
        box = text.get_window_extent(renderer)
        inside = frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
        cost = (0 if inside else 10_000) + points_in_box(points, box, pad_px) + 1_000 * sum(
            boxes_overlap(box, other, pad_px) for other in boxes)
        if cost == 0:
            if best is not None:
                best.remove()
            return text
        if best_cost is None or cost < best_cost:
            if best is not None:
                best.remove()
            best, best_cost = text, cost
        else:
            text.remove()
    return best


def label_vertical_marks(ax: Any, marks: dict[str, Any], **style: Any) -> list[Any]:
    """Label each vertical line of ``marks`` (label -> the ``axvline``) along its side, rotated,
    where the text clears every line, marker, the legend and the labels placed before it: the
    right side first, then the left, from the bottom up, then from the top down. Returns the
    texts. Call it once the figure's layout is final."""
    ax.figure.canvas.draw()
    renderer = ax.figure.canvas.get_renderer()
    legend = ax.get_legend()
    boxes = [legend.get_window_extent(renderer)] if legend is not None else []
    points = drawn_points(ax)
    texts = []
    for label, line in marks.items():
        x = line.get_xdata()[0]
        candidates = [dict(text=label, xy=(x, y), xycoords=("data", "axes fraction"), xytext=(3 * side, 0),
                           textcoords="offset points", rotation=90, ha="left" if side > 0 else "right", va=va,
                           **{"fontsize": 7, "color": "grey", **style})
                      for y, va in ((0.02, "bottom"), (0.3, "bottom"), (0.98, "top"))
                      for side in (1, -1)]
        text = place_clear(ax, candidates, boxes, points)
        boxes.append(text.get_window_extent(renderer))
        texts.append(text)
    return texts
