"""The tolerance table: for each cup (lip compliance S, cup radius) and each twist-off torque, the
largest stem-axis error the scripted suction picker tolerates on SMS3DPick-v2 (harvest-ready
targets, held-out 25-mushroom beds from seed 1,000,000, exact cap top).

"Tolerated" means a clean success in at least 90 % of the episodes at that error and at every
smaller error tried; the table gives that error, the success there with its 95 % Wilson
interval, the first error below 90 % with its success, and atan(S / D), the lip's geometric
limit (D the cup's diameter). Each (robot, cup, torque, error) cell runs in a worker process.

Usage: python benchmarks/bench_tolerance_table.py [--robots gantry] [--lip-compliance 0.003 0.005 0.007]
       [--cup-radius 0.010] [--twist-torque 0.015 0.03 0.06] [--errors 0 4 8 12 16 20]
       [--episodes 40] [--workers 2] [--json FILE]
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
from multiprocessing import get_context
from pathlib import Path

from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).parent))
from bench_robots import run_cell  # noqa: E402

from sms3d_env.robots import registered_robots  # noqa: E402
from sms3d_env.study.statistics import wilson_interval  # noqa: E402

#: Success share an error must reach (at it and every smaller error) to be tolerated.
TOLERATED_SHARE = 0.9


def _cell(args: tuple) -> dict:
    robot, error, episodes, physics = args
    row = run_cell(robot, error, episodes, physics=physics)
    row.pop("outcomes")
    return row


def tolerance(rows: list[dict]) -> dict:
    """The tolerated error of one (robot, cup, torque) group of rows (one per error)."""
    rows = sorted(rows, key=lambda r: r["error_deg"])
    tolerated, first_below = None, None
    for row in rows:
        if row["success"] >= TOLERATED_SHARE * row["episodes"]:
            tolerated = row
        else:
            first_below = row
            break
    return {"tolerated": tolerated, "first_below": first_below}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", nargs="+", default=["gantry"], choices=registered_robots())
    ap.add_argument("--lip-compliance", type=float, nargs="+", default=[0.003, 0.005, 0.007], help="S (m)")
    ap.add_argument("--cup-radius", type=float, nargs="+", default=[0.010], help="m")
    ap.add_argument("--twist-torque", type=float, nargs="+", default=[0.015, 0.03, 0.06], help="N m")
    ap.add_argument("--errors", type=float, nargs="+", default=[0, 4, 8, 12, 16, 20], help="deg")
    ap.add_argument("--episodes", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=None, help="also write the rows here")
    args = ap.parse_args()
    groups = list(itertools.product(args.robots, args.lip_compliance, args.cup_radius, args.twist_torque))
    cells = [(robot, e, args.episodes, {"lip_compliance": s, "cup_radius": a, "twist_torque": t})
             for robot, s, a, t in groups for e in args.errors]
    with get_context("spawn").Pool(args.workers) as pool:
        rows = list(tqdm(pool.imap(_cell, cells), total=len(cells), desc="cells"))
    print("| robot | S (mm) | cup (mm) | twist-off (N m) | atan(S/D) (deg) | tolerated (deg) | success there (95 % CI) | first below 90 % |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    table = []
    for robot, s, a, t in groups:
        mine = [r for r in rows if r["robot"] == robot and r["physics"] == {"lip_compliance": s, "cup_radius": a,
                                                                            "twist_torque": t}]
        tol = tolerance(mine)
        ok, below = tol["tolerated"], tol["first_below"]
        if ok is None:
            at = "none"
        else:
            lo, hi = wilson_interval(ok["success"], ok["episodes"])
            at = f"{ok['success']}/{ok['episodes']} ({lo:.0%}–{hi:.0%})"
        worse = "none tried" if below is None else f"{below['error_deg']:g}°: {below['success']}/{below['episodes']}"
        geometric = math.degrees(math.atan(s / (2 * a)))
        print(f"| {robot} | {s * 1e3:g} | {2 * a * 1e3:g} | {t:g} | {geometric:.1f} | "
              f"{'< ' + format(min(args.errors), 'g') if ok is None else format(ok['error_deg'], 'g')} | {at} | {worse} |")
        table.append({"robot": robot, "lip_compliance": s, "cup_radius": a, "twist_torque": t,
                      "tolerated_deg": None if ok is None else ok["error_deg"], "rows": mine})
    if args.json:
        Path(args.json).write_text(json.dumps(table, indent=1), encoding="utf-8")


if __name__ == "__main__":
    main()
