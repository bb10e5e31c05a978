"""Pose error against a mushroom's angles and size (the SMS3D paper's Figures 9–10).

``plot_errors`` bins each error series by roll, pitch and yaw (degrees) and by cap diameter
(millimetres) into equal-count bins and plots the bin means; it writes
``error_vs_angles.png`` and ``error_vs_size.png`` and returns their paths.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np


def binned_means(x: np.ndarray, y: np.ndarray, bins: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``x`` and mean ``y`` of ``bins`` equal-count bins of ``x``."""
    edges = np.quantile(x, np.linspace(0, 1, bins + 1))
    centres, means = [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (x >= lo) & (x <= hi)
        if sel.any():
            centres.append(x[sel].mean())
            means.append(y[sel].mean())
    return np.array(centres), np.array(means)


def _plot_series(ax, x: np.ndarray, errors: Mapping[str, np.ndarray]) -> None:
    for label, y in errors.items():
        ax.plot(*binned_means(x, y), "o-", label=label)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)


def plot_errors(
    errors: Mapping[str, np.ndarray], meta: Sequence[dict], out: str | Path, title: str = ""
) -> tuple[Path, Path]:
    """Plot each ``errors[label]`` (degrees, one per sample) against the samples' ``meta``
    angles (``roll``, ``pitch``, ``yaw`` in radians) and ``cap_diameter`` (metres)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    angles_png, size_png = out / "error_vs_angles.png", out / "error_vs_size.png"
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), sharey=True)
    for ax, key in zip(axes, ("roll", "pitch", "yaw"), strict=True):
        _plot_series(ax, np.degrees([m[key] for m in meta]), errors)
        ax.set_xlabel(f"{key} (°)")
    axes[0].set_ylabel("mean error (°)")
    axes[0].legend()
    fig.suptitle(f"Pose error vs mushroom angles — {title}")
    fig.tight_layout()
    fig.savefig(angles_png, dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(5, 3.6))
    _plot_series(ax, np.array([m["cap_diameter"] for m in meta]) * 1e3, errors)
    ax.set_xlabel("cap diameter (mm)")
    ax.set_ylabel("mean error (°)")
    ax.legend()
    ax.set_title(f"Pose error vs size\n{title}", fontsize=10)
    fig.tight_layout()
    fig.savefig(size_png, dpi=110)
    plt.close(fig)
    return angles_png, size_png
