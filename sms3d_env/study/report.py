"""The report of the pose-error sweep: the CSV, the 1-D curve (PNG) and the Markdown summary,
with the 2-D success map and the slices (:mod:`~sms3d_env.study.success_map`) when the sweep has
them (``write_report``). The numbers are :mod:`~sms3d_env.study.statistics`'s, the figure helpers
:mod:`~sms3d_env.study.figures`'s."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from generator.files import write_atomic
from sms3d_env.pickers.registry import picker_name
from sms3d_env.study import success_map
from sms3d_env.study.figures import (
    ORIENTATION_LABEL,
    draw_curve,
    label_vertical_marks,
    plot_curves,
    save_figure,
)
from sms3d_env.study.statistics import (
    TILTED_DEG,
    WITHIN_PP,
    RowAxes,
    axes,
    crowded_threshold,
    perception_point,
    success_table,
    tolerable_error,
)

PAPER_ERRORS_DEG = {"SMS3D synthetic (Point Transformer)": 1.67, "SMS3D real (M18K)": 3.68}

CSV_COLUMNS = ("variant", "picker", "robot", "tool", "num_mushrooms", "source", "error_deg", "position_error_mm",
               "axis_error_deg", "cap_top_error_mm", "seed", "target", "reachable", "success",
               "failure_cause", "tilt_deg", "cap_diameter", "nn_distance", "steps", "return", "neighbours_disturbed",
               "bruised", "target_detached", "time_s")


def write_csv(rows: Sequence[dict[str, Any]], path: str | Path) -> None:
    import csv

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(Path(path), buffer.getvalue())


def plot_sweep(rows: Sequence[dict[str, Any]], path: str | Path, perception: dict[str, float] | None = None) -> None:
    """Success vs pose error with 95 % intervals (one line per physics variant) above the
    failure causes of the default physics, stacked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = success_table(rows)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 7.5), sharex=True, height_ratios=[3, 2])
    for variant in dict.fromkeys(r["variant"] for r in table):
        draw_curve(top, [r for r in table if r["variant"] == variant], variant, lw=2 if variant == "default" else 1)
    marks = {f"{label}: {err}°": top.axvline(err, ls=":", color="grey") for label, err in PAPER_ERRORS_DEG.items()}
    if perception:
        top.errorbar([perception["error_deg"]], [100 * perception["success"]],
                     xerr=[[perception["error_deg"] - perception["p10_error_deg"]],
                           [perception["p90_error_deg"] - perception["error_deg"]]],
                     yerr=[[100 * (perception["success"] - perception["ci_low"])],
                           [100 * (perception["ci_high"] - perception["success"])]],
                     fmt="*", ms=14, color="k", capsize=3,
                     label="perception source (mean axis error; bar: 10th-90th percentile)")
    top.set_ylabel("pick success (%)")
    top.set_ylim(0, 105)
    top.grid(alpha=0.3)
    top.legend(fontsize=8, loc="lower left")
    pickers = sorted({picker_name(r.get("picker", "scripted")) for r in rows})
    robot, tool, size, target, _ = axes(rows[0])
    top.set_title(f"{', '.join(pickers).capitalize()} on the {robot} ({tool}, {size} mushrooms{success_map.target_words(target)}):\n"
                  "pick success vs orientation error")
    default = [r for r in table if r["variant"] == "default"]
    causes = sorted({c for r in default for c in r["causes"]})
    bottom_acc = np.zeros(len(default))
    x = np.array([r["error_deg"] for r in default])
    width = np.maximum(0.6, 0.12 * np.diff(np.r_[x, x[-1] + 5]).min()) if len(x) else 0.6
    for cause in causes:
        share = np.array([100 * r["causes"].get(cause, 0) / r["n"] for r in default])
        bottom.bar(x, share, width=width, bottom=bottom_acc, label=cause)
        bottom_acc += share
    bottom.set_xlabel(ORIENTATION_LABEL)
    bottom.set_ylabel("failures (% of episodes)")
    bottom.grid(alpha=0.3)
    if causes:
        bottom.legend(fontsize=8)
    fig.tight_layout()
    label_vertical_marks(top, marks)  # placed once the layout is final, clear of the lines and legend
    save_figure(fig, path)


def plot_pickers(curves: dict[str, Sequence[dict[str, Any]]], path: str | Path) -> None:
    """One line per picker: the sweeps of several pickers on the same seeded episodes, each the
    rows of one physics variant and position error (``compare.compared_rows``)."""
    plot_curves({label: success_table(rows) for label, rows in curves.items()}, path,
                "Pickers on the same seeded episodes: success vs orientation error")


def summarise(rows: Sequence[dict[str, Any]], command: str = "", perception: dict[str, float] | None = None) -> str:
    """The Markdown answer: largest tolerable error overall, for tilted and for crowded targets."""
    crowded = crowded_threshold(rows)
    subsets = {
        "all reachable targets": lambda r: True,
        f"tilted > {TILTED_DEG:g}°": lambda r: r["tilt_deg"] > TILTED_DEG,
        f"crowded (nearest neighbour < {1000 * crowded:.0f} mm)": lambda r: r["nn_distance"] < crowded,
    }
    lines = ["# How accurate must the orientation estimate be?", ""]
    if command:
        lines += [f"Reproduce: `{command}`", ""]
    picker = ", ".join(sorted({r.get("picker", "scripted") for r in rows}))
    lines += [f"Answer: the largest orientation error at which the {picker} picker's success stays within "
              f"{WITHIN_PP:g} percentage points of its success with exact (oracle) poses.", "",
              "| physics | subset | oracle success | tolerable error | episodes per error |", "| --- | --- | --- | --- | --- |"]
    for variant in dict.fromkeys(r["variant"] for r in rows):
        for label, keep in subsets.items():
            table = [t for t in success_table(rows, keep) if t["variant"] == variant]
            if not table:
                continue
            tol = tolerable_error(table, variant)
            oracle = next((t for t in table if t["error_deg"] == 0.0), None)
            oracle_text = "n/a" if oracle is None else f"{100 * oracle['success']:.0f} %"
            tol_text = "n/a" if tol is None else f"{tol:g}°"
            counts = [t["n"] for t in table]
            lines.append(f"| {variant} | {label} | {oracle_text} | {tol_text} | {min(counts)}–{max(counts)} |")
    lines += ["", "Success rate per error (default physics, all reachable targets, 95 % Wilson interval):", "",
              "| error | success | 95 % CI | n | failure causes | failures that knocked the target off its root |",
              "| --- | --- | --- | --- | --- | --- |"]
    for t in success_table(rows):
        if t["variant"] == "default":
            causes = ", ".join(f"{k} {v}" for k, v in sorted(t["causes"].items())) or "–"
            lines.append(f"| {t['error_deg']:g}° | {100 * t['success']:.1f} % | {100 * t['ci_low']:.1f}–{100 * t['ci_high']:.1f} % "
                         f"| {t['n']} | {causes} | {t['knocked_off']} |")
    default_table = [t for t in success_table(rows) if t["variant"] == "default"]
    tol = tolerable_error(default_table) if default_table else None
    if tol is not None:
        lines += ["", "The SMS3D paper's reported errors against this answer:"]
        for label, err in PAPER_ERRORS_DEG.items():
            verdict = "within" if err <= tol else "beyond"
            lines.append(f"- {label}: {err}° — {verdict} the tolerable {tol:g}°.")
    if perception:
        lines += ["", f"Perception pose source (the shipped axis CNN on the masks of the stage-1 detector "
                      f"the sweep names, `--perception-detector`: the shipped RGB-D segmenter by default; "
                      f"`--perception-realism`: with the camera model): stem-axis error mean "
                      f"{perception['error_deg']:.1f}°, median {perception['median_error_deg']:.1f}°, 90th percentile "
                      f"{perception['p90_error_deg']:.1f}°; success {100 * perception['success']:.1f} % "
                      f"({100 * perception['ci_low']:.1f}–{100 * perception['ci_high']:.1f} %) over {perception['n']} episodes."]
    return "\n".join(lines) + "\n"


def base_slice(rows: Sequence[dict[str, Any]]) -> RowAxes:
    """The axes of the 1-D report: the noisy-source rows' first robot in the registered robots' order
    (``registered_robots()``, sorted; rows of a sweep's part files come sorted by name), their
    first tool and bed size in row order, the smallest position error."""
    from sms3d_env.robots import registered_robots

    noisy = [axes(r) for r in rows if r.get("source", "noisy") == "noisy"] or [axes(r) for r in rows]
    # min() keeps the first of equal keys: panels of one robot stay in row order.
    robots = registered_robots()
    panel = min(dict.fromkeys(a.panel for a in noisy), key=lambda p: robots.index(p[0]) if p[0] in robots else len(robots))
    return RowAxes(*panel, min(a.position_error_mm for a in noisy if a.panel == panel))


def write_report(rows: Sequence[dict[str, Any]], out: str | Path, command: str = "") -> dict[str, Path]:
    """CSV (every row), PNG and Markdown summary into ``out``; returns their paths. The curve
    and its summary are those of ``base_slice``; a sweep over position errors adds the success
    map per robot, tool and bed size (``sweep_map.png`` for the first, ``sweep_map_<panel>.png``
    for the others), one over robots, tools or bed sizes their slices (``sweep_slices.png``), and
    the summary states the tolerance region (:mod:`sms3d_env.study.success_map`). Each file is replaced
    atomically; if any of them fails, none is left (see below)."""
    out = Path(out)
    first = base_slice(rows)
    panel = [r for r in rows if axes(r).panel == first.panel]
    base = [r for r in panel if r.get("source") == "perception" or axes(r) == first]
    perception = perception_point(base)
    paths = {"csv": out / "sweep.csv", "png": out / "sweep.png", "md": out / "summary.md",
             "map": out / "sweep_map.png", "slices": out / "sweep_slices.png"}
    try:
        write_csv(rows, paths["csv"])
        plot_sweep(base, paths["png"], perception)
        text = summarise(base, command, perception)
        paths["map"].unlink(missing_ok=True)
        panels = success_map.panels(rows)
        for key, group in panels.items():
            if len({axes(r).position_error_mm for r in group}) > 1:
                label = success_map.panel_label(key)
                # The first panel's map keeps the historic name; the others are named by panel.
                if key != first.panel:
                    paths[f"map {label}"] = out / f"sweep_map_{success_map.panel_slug(key)}.png"
                success_map.plot_map(group, paths["map" if key == first.panel else f"map {label}"], label)
                text += success_map.region_summary(group, label)
        if len(panels) > 1:
            success_map.plot_slices(rows, paths["slices"])
            text += success_map.slices_summary(rows)
        else:
            paths["slices"].unlink(missing_ok=True)
        text += success_map.cycle_time_summary(rows)
        write_atomic(paths["md"], text)
    except BaseException:
        # Files of an earlier report beside this one's would be read as describing these rows.
        for path in paths.values():
            path.unlink(missing_ok=True)
        raise
    return {k: p for k, p in paths.items() if p.exists()}
