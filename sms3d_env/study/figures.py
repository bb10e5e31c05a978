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
