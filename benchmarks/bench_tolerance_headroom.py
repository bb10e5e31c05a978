"""How much can any picker gain over the scripted one under orientation error? The scripted picker
given the *true* pose in some of its phases (what a picker that inferred the truth perfectly
could do), and with a stall escape (what getting out of the approach's IK stalls is worth).

Rows, each on the same seeded episodes (25-mushroom beds, ``ControllerConfig(posture_target="tool")``,
the env the learned pickers are compared in):
- ``scripted``: the study's picker on the estimate (the reference of the McNemar tests);
- ``truth: approach``: the true pose while approaching, the estimate from the descent on;
- ``truth: descend + twist``: the estimate while approaching, the truth from the descent on
  (what correction by contact after the approach could at best give);
- ``truth: all``: the true pose throughout (the ceiling of pose inference);
- ``stall escape``: the estimate, but a stalled approach (the tool moved < 1 mm over 10 control
  steps within 2 cm of the stand-off point) starts the descent from where the arm is;
- ``truth: all + stall escape``.

Seeds 3,000,000 + i by default (disjoint from the held-out 1,000,000 + i that evaluate pickers).

Usage: python benchmarks/bench_tolerance_headroom.py [--errors 0 20 30] [--episodes 100]
       [--beds 25] [--seed 3000000]
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import Counter
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # runs from a checkout

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import generator  # noqa: E402
from sms3d_env.pickers.episode import run_episode  # noqa: E402
from sms3d_env.pickers.registry import PickerSpec, make_picker_env  # noqa: E402
from sms3d_env.pickers.scripted import ScriptedPicker  # noqa: E402
from sms3d_env.study.statistics import mcnemar_p, wilson_interval  # noqa: E402
from sms3d_env.training.demonstrations import with_true_target  # noqa: E402

ALL_PHASES = frozenset({"approach", "descend", "settle", "twist", "lift"})
ROWS = {  # row -> (phases driven by the true pose, stall escape)
    "scripted": (frozenset(), False),
    "truth: approach": (frozenset({"approach"}), False),
    "truth: descend + twist": (frozenset({"descend", "twist"}), False),
    "truth: all": (ALL_PHASES, False),
    "stall escape": (frozenset(), True),
    "truth: all + stall escape": (ALL_PHASES, True),
}


class StallEscapingPicker(ScriptedPicker):
    """The scripted picker, but an approach that has stalled near its goal starts the descent."""

    window, still, radius = 10, 0.001, 0.02  # control steps, m, m

    def reset(self) -> None:
        super().reset()
        self.trail: list[np.ndarray] = []

    def _approach(self, o):  # noqa: ANN001, ANN202  (ScriptedPicker's private phase signature)
        self.trail.append(o.p.copy())
        stalled = (len(self.trail) > self.window
                   and np.linalg.norm(self.trail[-1] - self.trail[-1 - self.window]) < self.still)
        if stalled and np.linalg.norm(self.approach_goal(o) - o.p) < self.radius:
            self.phase = "descend"
            return self._descend(o)
        return super()._approach(o)


class TruthInPhases:
    """``picker`` acting on the true target pose while in one of ``phases`` (a run_episode policy)."""

    def __init__(self, env, picker: ScriptedPicker, phases: frozenset[str]) -> None:  # noqa: ANN001
        self.env, self.picker, self.phases = env, picker, phases

    def reset(self) -> None:
        self.picker.reset()

    def __call__(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        if self.picker.phase in self.phases:
            obs = with_true_target(self.env, obs, self.env.unwrapped.picking.state.target)
        return self.picker(obs)


def run(error: float, truth_phases: frozenset[str], escape: bool, beds: int, episodes: int,
        seed: int) -> list[tuple[int, bool, str]]:
    """``(seed, success, failure cause)`` per episode whose target is reachable."""
    kw = {"pose_source": "noisy", "pose_error_deg": error} if error > 0 else {}
    env, picker = make_picker_env(PickerSpec("scripted"), controller={"posture_target": "tool"},
                                  scene=generator.SceneConfig().replace(placement__num_mushrooms=beds), **kw)
    if escape:
        u = env.unwrapped
        picker = StallEscapingPicker(u.ctrl_cfg.max_linear_speed, u.ctrl_cfg.max_angular_speed, u.control_dt)
    policy = TruthInPhases(env, picker, truth_phases)
    try:
        results = [run_episode(env, policy, s) for s in range(seed, seed + episodes)]
    finally:
        env.close()
    return [(r["seed"], r["success"], r["failure_cause"]) for r in results if r["reachable"]]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--errors", type=float, nargs="+", default=[0.0, 20.0, 30.0], help="orientation errors (deg)")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--beds", type=int, default=25, help="mushrooms per bed")
    p.add_argument("--seed", type=int, default=3_000_000, help="first episode seed")
    p.add_argument("--rows", nargs="+", default=list(ROWS), choices=list(ROWS), metavar="ROW",
                   help="rows besides the scripted picker, which always runs first (the reference)")
    args = p.parse_args()
    names = ["scripted"] + [r for r in args.rows if r != "scripted"]
    print("| error | picker | success | 95 % Wilson | failures | only this / only scripted | McNemar p |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for error in args.errors:
        reference = None
        for name in tqdm(names, desc=f"{error:g} deg", leave=False):
            rows = run(error, *ROWS[name], args.beds, args.episodes, args.seed)
            wins = {s: ok for s, ok, _ in rows}
            k, n = sum(wins.values()), len(wins)
            lo, hi = wilson_interval(k, n)
            causes = ", ".join(f"{c} {m}" for c, m in Counter(c for _, ok, c in rows if not ok).most_common())
            if reference is None:
                reference, versus = wins, "— | —"
            else:
                paired = sorted(set(wins) & set(reference))
                b = sum(wins[s] and not reference[s] for s in paired)
                c = sum(reference[s] and not wins[s] for s in paired)
                p_value = mcnemar_p([wins[s] for s in paired], [reference[s] for s in paired])
                versus = f"{b} / {c} | {p_value:.2g}"
            print(f"| {error:g}° | {name} | {k}/{n} | {100 * lo:.1f}–{100 * hi:.1f} % | {causes or '—'} | {versus} |",
                  flush=True)


if __name__ == "__main__":
    main()
