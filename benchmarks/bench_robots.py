"""The scripted picker on SMS3DPick-v2 (or ``--env-id``) for each robot and orientation error:
successes, failure causes, and the cycle time (simulated seconds from reset to a successful lift,
median and 90th percentile, and the median of its phases: to the grip, the twist until the root
let go, the lift), over held-out seeded 25-mushroom beds (seeds from 1,000,000). Each (robot,
error) cell runs in a worker process.

Usage: python benchmarks/bench_robots.py [--episodes 200] [--robots gantry jaco]
       [--errors 0 10 20 30] [--substeps 10] [--target RULE] [--physics lip_compliance=0.003 ...]
       [--env-id SMS3DPick-v2] [--workers 2] [--json FILE]

``--physics NAME=VALUE`` sets fields of ``PickPhysicsParams`` (e.g. ``lip_compliance=0.003
twist_torque=0.06``) over the env's own, the robot's cup radius kept unless given; ``--target``
the env's target rule (default: the env's, harvest-ready on v2).

``--json`` also keeps each episode's outcome (success or failure cause, by seed), so that two runs
that differ in one setting (e.g. ``--substeps``) compare episode by episode.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
from multiprocessing import get_context

import numpy as np
from tqdm import tqdm

from sms3d_env.controller import ControllerConfig
from sms3d_env.robots import registered_robots

os.environ.setdefault("MUJOCO_GL", "egl")

HELD_OUT_SEED = 1_000_000


def physics_overrides(items: list[str]) -> dict[str, float]:
    """``["lip_seal=1", "lip_compliance=0.003"]`` as ``PickPhysicsParams`` field values (the
    field's own type: a bool field reads 0/1/true/false); ``SystemExit`` naming a bad item."""
    import dataclasses

    from sms3d_env.physics_params import PickPhysicsParams

    fields = {f.name: f.type for f in dataclasses.fields(PickPhysicsParams)}
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or name not in fields:
            raise SystemExit(f"--physics: {item!r} is not NAME=VALUE with NAME a PickPhysicsParams field "
                             f"({', '.join(fields)})")
        try:
            out[name] = (value.lower() in ("1", "true")) if fields[name] == "bool" else float(value)
        except ValueError:
            raise SystemExit(f"--physics: {name} needs a number, got {value!r}") from None
    return out


def run_cell(robot: str, error_deg: float, episodes: int, substeps: int = ControllerConfig.substeps,
             target: str | None = None, physics: dict | None = None, env_id: str = "SMS3DPick-v2",
             tool: str | None = None) -> dict:
    from dataclasses import replace

    import gymnasium as gym

    import sms3d_env  # noqa: F401  (registers the ids)
    from sms3d_env.pickers.episode import run_episode
    from sms3d_env.pickers.scripted import ScriptedPicker

    kwargs = {k: v for k, v in (("target", target), ("tool", tool)) if v is not None}
    env = gym.make(env_id, robot=robot, scene={"placement": {"num_mushrooms": 25}},
                   pose_source="noisy" if error_deg else "oracle", pose_error_deg=error_deg,
                   controller=ControllerConfig(substeps=substeps), **kwargs)
    if physics:  # the env's own defaults for its robot (its cup radius), with these fields set
        params = replace(env.unwrapped.params, **physics)
        env.close()
        env = gym.make(env.spec, physics=params)
    picker = ScriptedPicker.for_env(env)
    outcomes, times, phases = [], [], []
    for seed in range(HELD_OUT_SEED, HELD_OUT_SEED + episodes):
        result = run_episode(env, picker, seed)
        outcomes.append("success" if result["success"] else result["failure_cause"])
        if result["success"]:
            times.append(result["time_s"])
            phases.append((result["time_gripped_s"], result["time_detached_s"] - result["time_gripped_s"],
                           result["time_s"] - result["time_detached_s"]))
    causes = collections.Counter(outcomes)
    grip, twist, lift = np.median(phases, axis=0).tolist() if phases else (None, None, None)
    return {"robot": robot, "error_deg": error_deg, "episodes": episodes, "substeps": substeps,
            "env_id": env_id, "target": env.unwrapped.target_rule.rule, "tool": env.unwrapped.tool,
            "physics": physics or {},
            "success": causes.pop("success", 0), "failures": dict(causes),
            "time_median_s": float(np.median(times)) if times else None,
            "time_p90_s": float(np.percentile(times, 90)) if times else None,
            "phase_median_s": {"to_grip": grip, "twist": twist, "lift": lift},
            "first_seed": HELD_OUT_SEED, "outcomes": outcomes}


def _cell(args: tuple) -> dict:
    return run_cell(*args)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--robots", nargs="+", default=list(registered_robots()), choices=registered_robots())
    parser.add_argument("--errors", type=float, nargs="+", default=[0.0, 10.0, 20.0, 30.0])
    parser.add_argument("--substeps", type=int, default=ControllerConfig.substeps,
                        help="physics steps per 40 ms control step (ControllerConfig.substeps; default 10 x 4 ms)")
    parser.add_argument("--target", default=None, help="the env's target rule (default: the env's)")
    parser.add_argument("--env-id", default="SMS3DPick-v2", help="a registered SMS3DPick id (default SMS3DPick-v2)")
    parser.add_argument("--physics", nargs="*", default=[], metavar="NAME=VALUE",
                        help="PickPhysicsParams fields to set, e.g. lip_seal=1 lip_compliance=0.003")
    parser.add_argument("--tool", choices=["suction", "hand"], default=None,
                        help="the robot's tool (default: its own, the suction cup)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", default=None, help="also write the rows here")
    args = parser.parse_args()
    physics = physics_overrides(args.physics)
    cells = [(r, e, args.episodes, args.substeps, args.target, physics, args.env_id, args.tool)
             for r in args.robots for e in args.errors]
    with get_context("spawn").Pool(args.workers) as pool:
        # imap keeps the cells' order; the bar counts finished (robot, error) cells.
        rows = list(tqdm(pool.imap(_cell, cells), total=len(cells), desc="robot x error cells"))
    print("| robot | error (deg) | success | failures | cycle time median / p90 (s) | to grip / twist / lift (s) |")
    print("| --- | --- | --- | --- | --- | --- |")
    for row in rows:
        failures = ", ".join(f"{k} {v}" for k, v in sorted(row["failures"].items())) or "none"
        times = "n/a" if row["time_median_s"] is None else f"{row['time_median_s']:.2f} / {row['time_p90_s']:.2f}"
        ph = row["phase_median_s"]
        split = "n/a" if ph["to_grip"] is None else f"{ph['to_grip']:.2f} / {ph['twist']:.2f} / {ph['lift']:.2f}"
        print(f"| {row['robot']} | {row['error_deg']:g} | {row['success']}/{row['episodes']} | {failures} | {times} "
              f"| {split} |")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
