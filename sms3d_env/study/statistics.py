"""Statistics of the pose-error sweep's rows: binomial intervals and paired tests, the success
table per error, the 1-D tolerable error, the perception point and the crowding threshold.

Pure numbers (numpy; scipy for ``mcnemar_p``): the report (:mod:`~sms3d_env.study.report`), the
2-D answer (:mod:`~sms3d_env.study.success_map`), the sweep's comparisons and training's
evaluation read them; this module imports none of them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

TILTED_DEG = 30.0  # "tilted" mushrooms in the summary
WITHIN_PP = 5.0  # success within this many percentage points of the oracle counts as "enough"


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95 % Wilson score interval for a binomial proportion: ``lo <= successes / n <= hi``, both
    in [0, 1], ``hi`` exactly 1 for n/n and ``lo`` exactly 0 for 0/n."""
    if n == 0:
        return (math.nan, math.nan)
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # Exactly, the interval holds p and ends at 1 for n/n (0 for 0/n); rounding can leave an end
    # an ulp on the wrong side of p (4/4 gives 0.9999999999999999), a negative error bar.
    return (min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half)))


class RowAxes(NamedTuple):
    """A row's place on the sweep's axes besides the orientation error and the physics variant."""

    robot: str
    tool: str
    num_mushrooms: int
    target: str  # the env's target rule (sms3d_env.targets.TargetRule.rule)
    position_error_mm: float

    @property
    def panel(self) -> tuple[str, str, int, str]:
        """(robot, tool, bed size, target rule): the rows that share one 1-D curve and one 2-D map."""
        return self.robot, self.tool, self.num_mushrooms, self.target


#: The robot of rows recorded before the robot was an axis (they were made on the Jaco of the
#: removed SMS3DPick-v0; such rows are read, as results, and no env of theirs is built).
UNRECORDED_ROBOT = "jaco-v0"


#: The target rule of rows recorded before it was an axis: the default rule of the env they were
#: made on (harvest-ready on SMS3DPick-v2, the tallest mushroom on v1).
UNRECORDED_TARGET = "env default"


def axes(row: dict[str, Any]) -> RowAxes:
    """A row's robot, tool, bed size, target rule and cap-top position error (mm); rows of
    earlier sweeps hold only some of them (``UNRECORDED_ROBOT``, suction, 25 mushrooms,
    ``UNRECORDED_TARGET``, 0 mm)."""
    return RowAxes(row.get("robot", UNRECORDED_ROBOT), row.get("tool", "suction"), int(row.get("num_mushrooms", 25)),
                   row.get("target_rule", UNRECORDED_TARGET), float(row.get("position_error_mm", 0.0)))


def mcnemar_p(a: Sequence[bool], b: Sequence[bool]) -> float:
    """Two-sided exact McNemar p-value of paired outcomes ``a`` vs ``b`` (episode i of each on
    the same scene): the binomial test of the discordant pairs."""
    from scipy.stats import binomtest

    only_a = sum(x and not y for x, y in zip(a, b, strict=True))
    only_b = sum(y and not x for x, y in zip(a, b, strict=True))
    return 1.0 if only_a + only_b == 0 else float(binomtest(only_a, only_a + only_b, 0.5).pvalue)


def success_table(rows: Sequence[dict[str, Any]], keep: Callable[[dict[str, Any]], bool] = lambda r: True) -> list[dict[str, Any]]:
    """Success rate with its interval, failure-cause counts and ``knocked_off`` (failed episodes
    that left the target off its root: not left rooted for another try) per (variant, position
    error, orientation error), for rows of one panel (robot, tool and bed size)."""
    groups: dict[tuple[str, float, float], list[dict[str, Any]]] = {}
    for r in rows:
        if r["reachable"] and r.get("source", "noisy") == "noisy" and keep(r):
            groups.setdefault((r["variant"], axes(r).position_error_mm, r["error_deg"]), []).append(r)
    table = []
    for (variant, position, error), group in sorted(groups.items()):
        wins = sum(r["success"] for r in group)
        lo, hi = wilson_interval(wins, len(group))
        causes: dict[str, int] = {}
        for r in group:
            if not r["success"]:
                causes[r["failure_cause"] or "unknown"] = causes.get(r["failure_cause"] or "unknown", 0) + 1
        knocked_off = sum(not r["success"] and r.get("target_detached", False) for r in group)
        table.append({"variant": variant, "position_error_mm": position, "error_deg": error, "n": len(group),
                      "success": wins / len(group), "ci_low": lo, "ci_high": hi, "causes": causes,
                      "knocked_off": knocked_off})
    return table


def tolerable_error(table: Sequence[dict[str, Any]], variant: str = "default", within_pp: float = WITHIN_PP) -> float | None:
    """Largest error whose success, and that of every smaller error, stays within ``within_pp``
    percentage points of the zero-error (oracle) success; None without a zero-error row."""
    rows = sorted((r for r in table if r["variant"] == variant), key=lambda r: r["error_deg"])
    if not rows or rows[0]["error_deg"] != 0.0:
        return None
    oracle = rows[0]["success"]
    answer = 0.0
    for r in rows:
        if oracle - r["success"] > within_pp / 100.0 + 1e-9:  # "within" includes exactly 5 points
            break
        answer = r["error_deg"]
    return answer


def perception_point(rows: Sequence[dict[str, Any]]) -> dict[str, float] | None:
    """Success of the perception pose source with its measured stem-axis error (mean, median,
    10th and 90th percentiles), or None if the sweep ran no perception episodes."""
    runs = [r for r in rows if r.get("source") == "perception" and r["reachable"]]
    if not runs:
        return None
    errors = np.array([r["axis_error_deg"] for r in runs], dtype=float)
    wins = sum(r["success"] for r in runs)
    lo, hi = wilson_interval(wins, len(runs))
    return {"error_deg": float(errors.mean()), "median_error_deg": float(np.median(errors)),
            "p10_error_deg": float(np.percentile(errors, 10)), "p90_error_deg": float(np.percentile(errors, 90)),
            "success": wins / len(runs),
            "ci_low": lo, "ci_high": hi, "n": len(runs)}


def crowded_threshold(rows: Sequence[dict[str, Any]]) -> float:
    """Nearest-neighbour distance below which a target counts as crowded: the lowest quartile."""
    distances = [r["nn_distance"] for r in rows if math.isfinite(r["nn_distance"])]
    return float(np.percentile(distances, 25)) if distances else math.inf


def cycle_time(rows: Sequence[dict[str, Any]]) -> tuple[float, float, int]:
    """Median and 90th percentile (s) of the simulated time from reset to lift over the
    successful rows that record it, and how many there were (NaN, NaN, 0 without any)."""
    times = [float(r["time_s"]) for r in rows if r.get("success") and r.get("time_s") is not None]
    if not times:
        return math.nan, math.nan, 0
    return float(np.median(times)), float(np.percentile(times, 90)), len(times)

