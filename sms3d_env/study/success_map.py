"""The accuracy answer in two dimensions: success over (orientation error x cap-top position
error), the tolerance region, and the 1-D slices per tool and bed size.

Rows are the sweep's (``sweep.run_task``); every function reads the default physics
unless told a variant, and only reachable targets of the noisy source (the perception source's
rows are drawn as a cloud of measured errors).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sms3d_env.study.figures import (
    draw_curve,
    drawn_points,
    place_clear,
    plot_curves,
    polyline_points,
    save_figure,
    success_axes,
)
from sms3d_env.study.statistics import (
    TILTED_DEG,
    UNRECORDED_TARGET,
    WITHIN_PP,
    axes,
    crowded_threshold,
    cycle_time,
    success_table,
)

ISO_POINTS = (2.0, 5.0, 10.0)  # iso-lines of the map: oracle success minus these many points
TOOL_LINE_STYLES = ("-", "--", ":")
TOOL_MARKERS = ("o", "s", "^")


def success_grid(rows: Sequence[dict[str, Any]], variant: str = "default",
                 keep: Callable[[dict[str, Any]], bool] = lambda r: True) -> dict[str, Any]:
    """``{"errors_deg", "positions_mm", "success", "half_width", "n"}``: success (fraction) and
    the 95 % interval's half-width (fraction, the larger side) per (position, error) cell,
    arrays of shape (positions, errors); NaN where a cell has no episode."""
    table = [t for t in success_table(rows, keep) if t["variant"] == variant]
    errors = sorted({t["error_deg"] for t in table})
    positions = sorted({t["position_error_mm"] for t in table})
    shape = (len(positions), len(errors))
    success, half, n = np.full(shape, np.nan), np.full(shape, np.nan), np.zeros(shape, int)
    for t in table:
        i, j = positions.index(t["position_error_mm"]), errors.index(t["error_deg"])
        success[i, j] = t["success"]
        half[i, j] = max(t["success"] - t["ci_low"], t["ci_high"] - t["success"])
        n[i, j] = t["n"]
    return {"errors_deg": errors, "positions_mm": positions, "success": success, "half_width": half, "n": n}


def tolerance_region(grid: dict[str, Any], within_pp: float = WITHIN_PP) -> list[tuple[float, float]]:
    """The region within ``within_pp`` points of the oracle cell (0 deg, 0 mm) as a staircase:
    ``(B mm, A deg)`` pairs meaning "while the cap-top error is <= B mm, any axis error <= A deg
    keeps success within": A is the largest error whose cells, at every position error <= B and
    every error <= A, all are within. Empty without an oracle cell."""
    errors, positions, success = grid["errors_deg"], grid["positions_mm"], grid["success"]
    if not errors or not positions or errors[0] != 0.0 or positions[0] != 0.0 or np.isnan(success[0, 0]):
        return []
    ok = success >= success[0, 0] - within_pp / 100.0 - 1e-9  # "within" includes exactly the bound
    region = []
    for i, b in enumerate(positions):
        rows_ok = ok[: i + 1].all(axis=0)  # every position error up to b
        last = -1
        for j in range(len(errors)):
            if not rows_ok[j]:
                break
            last = j
        if last < 0:
            break
        region.append((b, errors[last]))
    return region


def region_sentence(region: list[tuple[float, float]], oracle: float, within_pp: float = WITHIN_PP) -> str:
    if not region:
        return f"no cell is within {within_pp:g} points of the oracle ({100 * oracle:.0f} %)"
    # A staircase step that keeps the same axis error is subsumed by the next, larger B.
    steps = [(b, a) for i, (b, a) in enumerate(region) if i + 1 == len(region) or region[i + 1][1] != a]
    parts = [f"axis error ≤ {a:g}° while the cap-top error is ≤ {b:g} mm" for b, a in steps]
    return f"within {within_pp:g} points of the oracle ({100 * oracle:.1f} %): " + "; or ".join(parts)


def _perception_cloud(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in rows if r.get("source") == "perception" and r["reachable"]
            and r.get("cap_top_error_mm") is not None]


def plot_map(rows: Sequence[dict[str, Any]], path: str | Path, panel: str = "", variant: str | None = None) -> None:
    """Heat map of success over (orientation error, cap-top error), each cell labelled with its
    success and 95 % half-width, iso-lines at the oracle minus 2, 5 and 10 points, and the
    perception source's measured (axis, cap-top) errors as a cloud with its own success.
    ``panel``: the robot, tool and bed size the rows share, for the title; ``variant``: the
    physics variant drawn (default: "default" if the sweep ran it, else its first)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if variant is None:
        variants = list(dict.fromkeys(r["variant"] for r in rows if r.get("source", "noisy") == "noisy"))
        variant = "default" if "default" in variants else variants[0]
    grid = success_grid(rows, variant)
    e, p, s = np.array(grid["errors_deg"]), np.array(grid["positions_mm"]), 100 * grid["success"]
    fig, ax = plt.subplots(figsize=(8, 5.5))
    # Cells drawn at their index (errors are uneven), labelled by value.
    im = ax.imshow(s, origin="lower", cmap="RdYlGn", vmin=max(0, np.nanmin(s) - 5), vmax=100, aspect="auto")
    cells = []
    for i in range(len(p)):
        for j in range(len(e)):
            if not np.isnan(s[i, j]):
                cells.append(ax.text(j, i, f"{s[i, j]:.0f}\n±{100 * grid['half_width'][i, j]:.0f}", ha="center",
                        va="center", fontsize=7))
    iso_lines = None
    oracle = s[0, 0] if e[0] == 0 and p[0] == 0 else np.nan
    if np.isfinite(oracle) and len(e) > 1 and len(p) > 1:
        levels = sorted(oracle - d for d in ISO_POINTS)
        cs = ax.contour(np.arange(len(e)), np.arange(len(p)), s, levels=levels, colors="k",
                        linewidths=[0.8, 1.6, 0.8][: len(levels)])
        iso_lines = (cs, [f"oracle − {oracle - lv:.0f}" for lv in levels])
    cloud = _perception_cloud(rows)
    if cloud:
        # Measured errors mapped onto the cell axes by interpolation between cell centres.
        x = np.interp([r["axis_error_deg"] for r in cloud], e, np.arange(len(e)))
        y = np.interp([r["cap_top_error_mm"] for r in cloud], p, np.arange(len(p)))
        picked = np.array([r["success"] for r in cloud], bool)
        ax.scatter(x[picked], y[picked], s=12, c="k", marker="o", label="perception: picked")
        ax.scatter(x[~picked], y[~picked], s=24, c="m", marker="x", label="perception: missed")
        ax.set_title(f"{panel + chr(10) if panel else ''}Pick success (%, ± 95 % half-width); perception "
                     f"{100 * picked.mean():.0f} % of {len(cloud)}")
        ax.legend(fontsize=7, loc="upper right")
    else:
        ax.set_title(f"{panel + chr(10) if panel else ''}Pick success (%, ± 95 % half-width) over orientation × "
                     f"cap-top error ({variant})")
    ax.set_xticks(range(len(e)), [f"{v:g}" for v in e])
    ax.set_yticks(range(len(p)), [f"{v:g}" for v in p])
    ax.set_xlabel("orientation error θ (degrees, perpendicular to the stem)")
    ax.set_ylabel("cap-top position error (mm)")
    fig.colorbar(im, ax=ax, label="success (%)")
    fig.tight_layout()
    if iso_lines:  # placed once the layout is final, clear of the cell numbers
        label_iso_lines(ax, *iso_lines, avoid=cells)
    save_figure(fig, path)


def label_iso_lines(ax: Any, contours: Any, labels: Sequence[str], avoid: Sequence[Any] = ()) -> list[Any]:
    """Label each level of ``contours`` once, on its line, where the label clears the texts of
    ``avoid`` (the cell numbers), the legend, the other levels' lines, the markers and the labels
    placed before it: the candidates run along the line from its middle outwards. Returns the
    labels (texts)."""
    ax.figure.canvas.draw()
    renderer = ax.figure.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in avoid]
    if ax.get_legend() is not None:
        boxes.append(ax.get_legend().get_window_extent(renderer))
    others = drawn_points(ax, skip=[contours])
    level_points = [[polyline_points(ax.transData.transform(seg), step_px=2.0) for seg in segs]
                    for segs in contours.allsegs]
    placed = []
    for k, label in enumerate(labels[: len(level_points)]):
        if not level_points[k]:
            continue
        points = np.concatenate([others] + [pts for m, segs in enumerate(level_points) if m != k for pts in segs])
        candidates = []
        for pts in sorted(level_points[k], key=len, reverse=True):
            along = pts[::3]
            middle = len(along) // 2
            for i in sorted(range(len(along)), key=lambda i: abs(i - middle)):
                x, y = ax.transData.inverted().transform(along[i])
                candidates.append(dict(text=label, xy=(x, y), ha="center", va="center", fontsize=7,
                                       bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.85)))
        text = place_clear(ax, candidates, boxes, points)
        boxes.append(text.get_window_extent(renderer))
        placed.append(text)
    return placed


def plot_slices(rows: Sequence[dict[str, Any]], path: str | Path) -> None:
    """Success vs orientation error (no position error, default physics), one line per (robot,
    tool, bed size) that the sweep ran: on one plot when only the robot varies, else one panel
    per robot with a colour per bed size and a line style per tool."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tables = {}
    for key, group in panels(rows).items():
        table = [t for t in success_table(group) if t["variant"] == "default" and t["position_error_mm"] == 0.0]
        if table:
            tables[key] = table
    robots = list(dict.fromkeys(robot for robot, *_ in tables))
    if len({key[1:] for key in tables}) <= 1:
        plot_curves({panel_label(key): table for key, table in tables.items()}, path,
                    "Success vs orientation error per robot")
        return
    beds = sorted({(size, target) for _, _, size, target in tables})  # a colour per bed size and target rule
    tools = sorted({tool for _, tool, _, _ in tables})
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.85, len(beds)))
    fig, axs = plt.subplots(1, len(robots), figsize=(5.5 * len(robots), 5), sharey=True, squeeze=False)
    # Curves that coincide (every suction cell at 100 %) stay visible: each is nudged sideways by
    # a fraction of the error spacing.
    errors = sorted({t["error_deg"] for table in tables.values() for t in table})
    spacing = min(np.diff(errors)) if len(errors) > 1 else 1.0
    for ax, robot in zip(axs[0], robots):
        for (r, tool, size, target), table in tables.items():
            if r != robot:
                continue
            bed = beds.index((size, target))
            k = tools.index(tool) * len(beds) + bed
            nudged = [{**t, "error_deg": t["error_deg"] + spacing * 0.03 * (k - len(tools) * len(beds) / 2)}
                      for t in table]
            draw_curve(ax, nudged, f"{tool}, {size} mushrooms{target_words(target)}", color=colours[bed],
                       ls=TOOL_LINE_STYLES[tools.index(tool) % len(TOOL_LINE_STYLES)],
                       marker=TOOL_MARKERS[tools.index(tool) % len(TOOL_MARKERS)])
        success_axes(ax)
        ax.set_title(robot)
        ax.legend(fontsize=8, loc="lower left")
    fig.suptitle("Success vs orientation error per tool, bed size and target (exact cap top, 95 % intervals)")
    fig.tight_layout()
    save_figure(fig, path)


Panel = tuple[str, str, int, str]  # robot, tool, bed size, target rule (statistics.RowAxes.panel)


def panels(rows: Sequence[dict[str, Any]]) -> dict[Panel, list[dict[str, Any]]]:
    """The rows grouped by (robot, tool, bed size, target rule), in sorted order."""
    groups: dict[Panel, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(axes(r).panel, []).append(r)
    return dict(sorted(groups.items()))


def target_words(target: str) -> str:
    """The target rule as a label's tail (``", crowded targets"``); nothing for rows that did not
    record it (``UNRECORDED_TARGET``)."""
    return "" if target == UNRECORDED_TARGET else f", {target.replace('_', '-')} targets"


def panel_label(key: Panel) -> str:
    robot, tool, size, target = key
    return f"{robot}, {tool}, {size} mushrooms{target_words(target)}"


def panel_slug(key: Panel) -> str:
    robot, tool, size, target = key
    return f"{robot}_{tool}_n{size}" + ("" if target in (UNRECORDED_TARGET, "harvest_ready") else f"_{target}")


def region_summary(rows: Sequence[dict[str, Any]], panel: str = "") -> str:
    """Markdown: the tolerance region per physics variant and subset (all, tilted, crowded),
    and the perception source's measured errors against it; ``panel`` names the robot, tool and
    bed size the rows share."""
    crowded = crowded_threshold(rows)
    subsets = {
        "all reachable targets": lambda r: True,
        f"tilted > {TILTED_DEG:g}°": lambda r: r["tilt_deg"] > TILTED_DEG,
        f"crowded (nearest neighbour < {1000 * crowded:.0f} mm)": lambda r: r["nn_distance"] < crowded,
    }
    lines = ["", f"## The tolerance region (orientation × cap-top position error){': ' + panel if panel else ''}", "",
             "| physics | subset | region | episodes per cell |", "| --- | --- | --- | --- |"]
    for variant in dict.fromkeys(r["variant"] for r in rows if r.get("source", "noisy") == "noisy"):
        for label, keep in subsets.items():
            grid = success_grid(rows, variant, keep)
            if not grid["errors_deg"]:
                continue
            oracle = grid["success"][0, 0]
            sentence = region_sentence(tolerance_region(grid), oracle)
            counts = grid["n"][grid["n"] > 0]
            lines.append(f"| {variant} | {label} | {sentence} | {counts.min()}–{counts.max()} |")
    cloud = _perception_cloud(rows)
    if cloud:
        axis = np.array([r["axis_error_deg"] for r in cloud])
        top = np.array([r["cap_top_error_mm"] for r in cloud])
        picked = np.mean([r["success"] for r in cloud])
        lines += ["", f"Perception source: axis error median {np.median(axis):.1f}° (90th percentile "
                      f"{np.percentile(axis, 90):.1f}°), cap-top error median {np.median(top):.1f} mm "
                      f"(90th percentile {np.percentile(top, 90):.1f} mm); picked {100 * picked:.1f} % of "
                      f"{len(cloud)}."]
    return "\n".join(lines) + "\n"


def slices_summary(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown: success per orientation error for every (robot, tool, bed size, target rule), no
    position error."""
    lines = ["", "## Slices per robot, tool, bed size and target (no position error, default physics)", "",
             "| robot | tool | mushrooms | targets | " + " | ".join(f"{e:g}°" for e in sorted({r['error_deg'] for r in rows
                                                                              if r.get('source', 'noisy') == 'noisy'})) + " |"]
    errors = sorted({r["error_deg"] for r in rows if r.get("source", "noisy") == "noisy"})
    lines.append("| --- | --- | --- | --- |" + " --- |" * len(errors))
    for (robot, tool, size, target), group in panels(rows).items():
        table = {t["error_deg"]: t for t in success_table(group)
                 if t["variant"] == "default" and t["position_error_mm"] == 0.0}
        cells = [f"{100 * table[e]['success']:.1f} % (n {table[e]['n']})" if e in table else "–" for e in errors]
        lines.append(f"| {robot} | {tool} | {size} | {target.replace('_', '-')} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def cycle_time_summary(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown: the cycle time (reset to lift, simulated) of the successful picks per robot,
    tool and bed size, at each orientation error (default physics, no position error)."""
    lines = ["", "## Cycle time of successful picks (simulated s from reset to lift: median / 90th percentile)", "",
             "| robot | tool | mushrooms | targets | error | median | p90 | picks |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for (robot, tool, size, target), group in panels(rows).items():
        base = [r for r in group if r.get("source", "noisy") == "noisy" and r["variant"] == "default"
                and axes(r).position_error_mm == 0.0]
        for error in sorted({r["error_deg"] for r in base}):
            median, p90, n = cycle_time([r for r in base if r["error_deg"] == error])
            if n:
                lines.append(f"| {robot} | {tool} | {size} | {target.replace('_', '-')} | {error:g}° | {median:.2f} | {p90:.2f} | {n} |")
    return "\n".join(lines) + "\n" if len(lines) > 4 else ""

