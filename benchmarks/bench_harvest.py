"""Scripted harvest planners side by side on SMS3DHarvest-v0: each pick order and re-scan rule
(``sms3d_env.harvest.orders``) on the same held-out beds (seeds from 4,000,000, disjoint from the
pickers' 1,000,000 and the headroom study's 3,000,000), with the yield (harvest-ready mushrooms
picked clean) and the damaged share of the bed pooled over the beds with 95 % Wilson intervals,
mushrooms per hour (mean over beds, 95 % t interval), missed, scans, attempts, and the wall time
per bed (each bed in one process on one core).

Usage: python benchmarks/bench_harvest.py [--beds 20] [--mushrooms 50] [--orders detection largest ...]
       [--rescans never after_failure ...] [--error 0] [--tray-on-head] [--workers 1] [--json FILE]

``--error`` > 0 takes the ``noisy`` pose source at that rotation error (deg); 0 exact poses.
``--tray-on-head``: ``HarvestConfig(collection_point=None)``, each picked mushroom dropped where it
was picked instead of carried to the tray beside the bed.
Pooled intervals treat every mushroom as independent; the mushrooms of one bed are not (a
KNOWN SIMPLIFICATION of the interval; the mean over beds is the safer comparison).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from multiprocessing import get_context

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")

HELD_OUT_SEED = 4_000_000


def run_bed(args: tuple[str, str, int, int, float, bool]) -> dict:
    """One bed (seed) harvested by one planner: its summary and wall time."""
    from sms3d_env.harvest import ScriptedOrder, SMS3DHarvestEnv, run_harvest

    order, rescan, seed, mushrooms, error, tray_on_head = args
    kwargs = {"pose_source": "noisy", "pose_error_deg": error} if error > 0 else {}
    if tray_on_head:
        kwargs["harvest"] = {"collection_point": None}
    env = SMS3DHarvestEnv(scene={"placement": {"num_mushrooms": mushrooms}}, **kwargs)
    start = time.perf_counter()
    row = run_harvest(env, ScriptedOrder(order, rescan), seed=seed)
    env.close()
    return {"order": order, "rescan": rescan, **row, "wall_s": time.perf_counter() - start}


def mean_interval(values: list[float]) -> tuple[float, float, float]:
    """Mean and 95 % t interval."""
    from scipy import stats

    x = np.asarray(values, float)
    if len(x) < 2:
        return float(x.mean()), math.nan, math.nan
    half = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x))
    return float(x.mean()), float(x.mean() - half), float(x.mean() + half)


def summarise(rows: list[dict]) -> dict:
    from sms3d_env.study.statistics import wilson_interval

    ready = sum(r["harvest_ready"] for r in rows)
    clean = sum(r["picked_clean_ready"] for r in rows)
    mushrooms = sum(r["mushrooms"] for r in rows)
    damaged = sum(r["damaged"]["ready"] + r["damaged"]["not_ready"] for r in rows)
    per_hour = mean_interval([r["mushrooms_per_hour"] for r in rows])
    return {
        "beds": len(rows), "harvest_ready": ready, "picked_clean_ready": clean,
        "yield": clean / ready, "yield_ci": wilson_interval(clean, ready),
        "damaged": damaged, "mushrooms": mushrooms, "damaged_share": damaged / mushrooms,
        "damaged_share_ci": wilson_interval(damaged, mushrooms),
        "damaged_ready": sum(r["damaged"]["ready"] for r in rows),
        "damaged_not_ready": sum(r["damaged"]["not_ready"] for r in rows),
        "missed": sum(r["missed"] for r in rows), "picked": sum(r["picked"] for r in rows),
        "mushrooms_per_hour": per_hour[0], "mushrooms_per_hour_ci": per_hour[1:],
        "scans": sum(r["scans"] for r in rows), "attempts": sum(r["attempts"] for r in rows),
        "retries": sum(r["retries"] for r in rows), "truncated": sum(r["truncated"] for r in rows),
        "wall_s_median": float(np.median([r["wall_s"] for r in rows])),
        "wall_s_max": float(max(r["wall_s"] for r in rows)),
    }


def main() -> None:
    from sms3d_env.harvest.orders import ORDERS, RESCANS

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--beds", type=int, default=20)
    parser.add_argument("--mushrooms", type=int, default=50)
    parser.add_argument("--orders", nargs="+", default=list(ORDERS), choices=ORDERS)
    parser.add_argument("--rescans", nargs="+", default=["never"], choices=RESCANS)
    parser.add_argument("--error", type=float, default=0.0, help="noisy pose error (deg); 0: exact poses")
    parser.add_argument("--tray-on-head", action="store_true", help="collection_point=None: no trip to the tray")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--json", default=None, help="also write every bed's row and the summaries here")
    args = parser.parse_args()
    cells = [(o, r, HELD_OUT_SEED + i, args.mushrooms, args.error, args.tray_on_head)
             for o in args.orders for r in args.rescans for i in range(args.beds)]
    with get_context("spawn").Pool(args.workers) as pool:
        rows = pool.map(run_bed, cells, chunksize=1)
    print(f"{args.beds} held-out {args.mushrooms}-mushroom beds (seeds {HELD_OUT_SEED}-{HELD_OUT_SEED + args.beds - 1}), "
          f"{'exact poses' if args.error == 0 else f'noisy {args.error:g} deg'}"
          f"{', a tray on the head' if args.tray_on_head else ', the tray beside the bed'}")
    print("| order / re-scan | yield (95 % CI) | damaged share of the bed (95 % CI) | missed | mushrooms per hour "
          "(95 % CI) | scans | attempts | wall s per bed (median / max) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    summaries = {}
    for o in args.orders:
        for r in args.rescans:
            s = summaries[f"{o}/{r}"] = summarise([x for x in rows if x["order"] == o and x["rescan"] == r])
            print(f"| {o} / {r} | {s['picked_clean_ready']}/{s['harvest_ready']} = {s['yield']:.1%} "
                  f"({s['yield_ci'][0]:.1%}–{s['yield_ci'][1]:.1%}) | {s['damaged']}/{s['mushrooms']} = "
                  f"{s['damaged_share']:.1%} ({s['damaged_share_ci'][0]:.1%}–{s['damaged_share_ci'][1]:.1%}) | "
                  f"{s['missed']} | {s['mushrooms_per_hour']:.0f} ({s['mushrooms_per_hour_ci'][0]:.0f}–"
                  f"{s['mushrooms_per_hour_ci'][1]:.0f}) | {s['scans']} | {s['attempts']} | "
                  f"{s['wall_s_median']:.1f} / {s['wall_s_max']:.1f} |")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump({"args": vars(args), "first_seed": HELD_OUT_SEED, "summaries": summaries, "beds": rows}, f,
                      indent=1)


if __name__ == "__main__":
    main()
