"""Pickers on the same seeded episodes: success with 95 % Wilson intervals, failure causes, and an
exact McNemar test of each picker against the first one (a paired design: every picker sees the
same scene, target and pose estimate in episode i).

Usage: python benchmarks/bench_policy.py --pickers scripted policy[:PATH] ... [--episodes 100]
       [--beds 10 25] [--errors 0] [--seed 2000000] [--robot gantry|jaco] [--json OUT.json]

Seeds 2,000,000 + i are disjoint from the demonstrations (0 ..) and from eval-policy's default
(1,000,000 + i).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # runs from a checkout

from tqdm import tqdm  # noqa: E402

from sms3d_env.pickers.episode import run_episode  # noqa: E402
from sms3d_env.pickers.registry import make_picker_env, parse_picker  # noqa: E402
from sms3d_env.robots import registered_robots  # noqa: E402
from sms3d_env.study.statistics import mcnemar_p, wilson_interval  # noqa: E402


def run(picker_text: str, beds: list[int], episodes: int, error: float, seed: int, robot: str | None) -> dict:
    spec = parse_picker(picker_text)
    outcomes, causes, t0 = [], {}, time.perf_counter()
    for n in beds:
        kw = {"scene": {"placement": {"num_mushrooms": n}}}  # the mapping form: the env completes the placement
        if error > 0:
            kw.update(pose_source="noisy", pose_error_deg=error)
        if robot is not None:
            kw["robot"] = robot
        env, picker = make_picker_env(spec, **kw)
        try:
            for i in tqdm(range(episodes), desc=f"{spec.label} {n} mushrooms {error:g} deg", leave=False):
                r = run_episode(env, picker, seed + i)
                outcomes.append(r["success"])
                if not r["success"]:
                    causes[r["failure_cause"]] = causes.get(r["failure_cause"], 0) + 1
        finally:
            env.close()
    return {"picker": spec.label, "error_deg": error, "outcomes": outcomes, "causes": causes,
            "wall_s": time.perf_counter() - t0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pickers", nargs="+", default=["scripted", "policy"])
    ap.add_argument("--episodes", type=int, default=100, help="episodes per bed size")
    ap.add_argument("--beds", type=int, nargs="+", default=[10, 25], help="mushrooms per bed")
    ap.add_argument("--errors", type=float, nargs="+", default=[0.0], help="pose errors (deg)")
    ap.add_argument("--seed", type=int, default=2_000_000)
    ap.add_argument("--robot", choices=registered_robots(), default=None,
                    help="the robot every picker acts on (default: the scripted picker's SMS3DPick-v2 gantry, "
                         "a learned picker's own)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)  # per-step inference of a small MLP: more threads only add overhead
    results = [run(p, args.beds, args.episodes, e, args.seed, args.robot) for e in args.errors for p in args.pickers]
    print(f"\n{args.episodes} episodes per bed x beds {args.beds}, seeds {args.seed}..; "
          f"p: exact McNemar against {results[0]['picker']} at the same error\n")
    print("| picker | pose error | success | 95 % CI | p vs first | failure causes | wall s |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for r in results:
        k, n = sum(r["outcomes"]), len(r["outcomes"])
        lo, hi = wilson_interval(k, n)
        first = next(x for x in results if x["error_deg"] == r["error_deg"])
        p = mcnemar_p(r["outcomes"], first["outcomes"])
        causes = ", ".join(f"{c} {m}" for c, m in sorted(r["causes"].items())) or "-"
        print(f"| {r['picker']} | {r['error_deg']:g}° | {k}/{n} = {100 * k / n:.1f} % | "
              f"{100 * lo:.1f}–{100 * hi:.1f} % | {p:.3g} | {causes} | {r['wall_s']:.0f} |")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
