"""Sweeps of several pickers side by side on the same seeded episodes: the rows compared, the
check that two sweeps ran the same episodes, and the paired table (exact McNemar p)."""

from __future__ import annotations

from typing import Any


def compared_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The episodes ``sweep-compare`` sets side by side: the noisy pose source with the default
    physics, in the sweep's base slice (its first tool and bed size, smallest position error)."""
    from sms3d_env.study.report import base_slice
    from sms3d_env.study.statistics import axes

    default = [r for r in rows if r.get("source", "noisy") == "noisy" and r["variant"] == "default"]
    if not default:
        return []
    base = base_slice(default)
    return [r for r in default if axes(r) == base]


def _spans(values: list[int]) -> str:
    """Sorted integers as runs: ``0–39`` or ``0, 2, 5–9``."""
    runs: list[list[int]] = []
    for v in values:
        if runs and v == runs[-1][1] + 1:
            runs[-1][1] = v
        else:
            runs.append([v, v])
    return ", ".join(f"{a}" if a == b else f"{a}–{b}" for a, b in runs)


def _design(rows: list[dict[str, Any]]) -> dict[str, str]:
    """What must be the same in two sweeps' ``compared_rows`` for their episodes to pair."""
    from sms3d_env.study.statistics import axes

    robot, tool, size, target, position = axes(rows[0])
    return {"robot": robot, "tool": tool, "bed size": f"{size} mushrooms", "target": target,
            "position error": f"{position:g} mm",
            "errors": ", ".join(f"{e:g}°" for e in sorted({r["error_deg"] for r in rows})),
            "seeds": _spans(sorted({int(r["seed"]) for r in rows})),
            "episodes": f"{len(rows)} (error, seed) pairs"}


def check_paired(sweeps: dict[str, list[dict[str, Any]]]) -> None:
    """ValueError naming the sweeps and the settings they differ in, unless every sweep's
    ``compared_rows`` ran the same seeded episodes as the first's: a comparison of other beds or
    seeds would pair nothing (McNemar p = nan) or unlike episodes."""
    (first, first_rows), *others = sweeps.items()
    episodes = {(r["error_deg"], r["seed"]) for r in first_rows}
    design = _design(first_rows)
    problems = []
    for folder, rows in others:
        theirs = _design(rows)
        differ = [k for k in design if design[k] != theirs[k]]
        if not differ and {(r["error_deg"], r["seed"]) for r in rows} != episodes:
            differ = ["episodes"]  # as many, but others (an unfinished sweep's)
        if not differ:
            continue
        problems.append(f"{folder}: " + ", ".join(f"{k} {theirs[k]} ({first}: {design[k]})" for k in differ))
    if problems:
        raise ValueError("the sweeps did not run the same seeded episodes, so they cannot be paired: "
                         + "; ".join(problems) + " (compare sweeps run with the same --num-mushrooms, --seed, "
                         "--episodes, --errors and --position-errors-mm)")


def picker_comparison(curves: dict[str, list[dict[str, Any]]]) -> str:
    """Markdown: each picker's success per orientation error on its ``compared_rows`` (reachable
    targets) and the exact McNemar p against the first picker on the episodes both ran (paired
    by seed)."""
    from sms3d_env.study.statistics import mcnemar_p, wilson_interval

    def outcomes(rows: list[dict[str, Any]]) -> dict[float, dict[int, bool]]:
        """Per error, seed -> success of the reachable targets."""
        by_error: dict[float, dict[int, bool]] = {}
        for r in rows:
            if r["reachable"]:
                by_error.setdefault(r["error_deg"], {})[r["seed"]] = bool(r["success"])
        return by_error

    first_label, *_ = curves
    first = outcomes(curves[first_label])
    lines = [f"| picker | error | success | 95 % CI | McNemar p vs {first_label} |", "| --- | --- | --- | --- | --- |"]
    for label, rows in curves.items():
        for error, wins in sorted(outcomes(rows).items()):
            k, n = sum(wins.values()), len(wins)
            lo, hi = wilson_interval(k, n)
            shared = sorted(set(wins) & set(first.get(error, {})))
            p = mcnemar_p([wins[s] for s in shared], [first[error][s] for s in shared]) if shared else float("nan")
            lines.append(f"| {label} | {error:g}° | {k}/{n} = {100 * k / n:.1f} % | {100 * lo:.1f}–{100 * hi:.1f} % | {p:.3g} |")
    return "\n".join(lines)
