"""Where the scripted picker fails under pose error: episodes whose approach never reaches the
stand-off point ("stalled": a reachable target, the episode run to its time limit, the picker
still in its approach phase), for each IK posture weight (``ControllerConfig.posture_cost``), on
the same seeded episodes.

The controller's posture task is a soft cost beside the tool's frame task, not a strict
null-space objective, so where the tool's motion costs much joint motion (near the Jaco's wrist
singularity) the posture's pull can balance the commanded motion. Each row: success among
reachable targets with its 95 % Wilson interval, stalled episodes, failure causes, and an exact
McNemar test against the first posture weight (paired by episode).

Seeds 3,000,000 + i by default: disjoint from the demonstrations (0 ..), eval-policy's default
(1,000,000 ..) and bench_policy.py's (2,000,000 ..), so a posture weight chosen here is not
tuned on the episodes that evaluate pickers.

Usage: python benchmarks/bench_approach_stalls.py [--errors 0 20 30] [--posture-costs 0.01 0.001]
       [--episodes 100] [--beds 25] [--seed 3000000]
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import Counter
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # runs from a checkout

from tqdm import tqdm  # noqa: E402

import generator  # noqa: E402
from sms3d_env.controller import ControllerConfig  # noqa: E402
from sms3d_env.pickers.registry import PickerSpec, make_picker_env  # noqa: E402
from sms3d_env.study.statistics import mcnemar_p, wilson_interval  # noqa: E402


def run(error: float, posture_cost: float, beds: int, episodes: int, seed: int) -> list[tuple[bool, str, bool]]:
    """``(success, failure cause, stalled)`` per episode whose target is reachable."""
    kw = {"pose_source": "noisy", "pose_error_deg": error} if error > 0 else {}
    env, picker = make_picker_env(PickerSpec("scripted"), controller=ControllerConfig(posture_cost=posture_cost),
                                  scene=generator.SceneConfig().replace(placement__num_mushrooms=beds), **kw)
    rows = []
    try:
        for s in tqdm(range(seed, seed + episodes), desc=f"{error:g} deg, posture {posture_cost:g}", leave=False):
            obs, info = env.reset(seed=s)
            picker.reset()
            terminated = truncated = False
            while not (terminated or truncated):
                obs, _, terminated, truncated, info = env.step(picker(obs))
            if info["reachable"]:
                # The picker's phases never return to the approach: its last phase says it all.
                rows.append((bool(info["is_success"]), info["failure_cause"], truncated and picker.phase == "approach"))
    finally:
        env.close()
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--errors", type=float, nargs="+", default=[0.0, 20.0, 30.0], help="orientation errors (deg)")
    p.add_argument("--posture-costs", type=float, nargs="+", default=[0.01, 0.001],
                   help="ControllerConfig.posture_cost values; the first is the reference (the default 0.01)")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--beds", type=int, default=25, help="mushrooms per bed")
    p.add_argument("--seed", type=int, default=3_000_000, help="first episode seed")
    args = p.parse_args()

    print(f"| error | posture cost | success | 95 % Wilson | stalled in the approach | failures | McNemar p vs {args.posture_costs[0]:g} |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for error in args.errors:
        reference = None
        for cost in args.posture_costs:
            rows = run(error, cost, args.beds, args.episodes, args.seed)
            wins = [r[0] for r in rows]
            lo, hi = wilson_interval(sum(wins), len(wins))
            causes = Counter(f"{cause}{' (stalled)' if stalled else ''}" for ok, cause, stalled in rows if not ok)
            if reference is None:
                reference, p_value = wins, "—"
            else:
                only_ref = sum(a and not b for a, b in zip(reference, wins, strict=True))
                only_this = sum(b and not a for a, b in zip(reference, wins, strict=True))
                p_value = f"{mcnemar_p(reference, wins):.2g} ({only_this} / {only_ref} only here / only there)"
            print(f"| {error:g}° | {cost:g} | {sum(wins)}/{len(wins)} | {100 * lo:.1f}–{100 * hi:.1f} % | "
                  f"{sum(r[2] for r in rows)} | {', '.join(f'{k} {v}' for k, v in causes.most_common()) or '—'} | {p_value} |",
                  flush=True)


if __name__ == "__main__":
    main()
