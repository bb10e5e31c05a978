"""Speed of SMS3DPick-v2 (or ``--version v1``): env steps/s with random actions and the
registered 250-step time limit, so the resets it triggers are in the rate (state observations,
50 mushrooms), reset time, and steps/s with 64 x 64 RGB-D observations; the training id's reset
with and without a scene pool. Anchor: FetchPickAndPlace-v4, measured by bench_fetch.py in its
own venv; with ``--fetch-python`` this script runs it before and after its own rows and prints
the ratio.

Usage: python benchmarks/bench_env.py [--steps 500] [--version v2] [--fetch-python /tmp/fetchenv/bin/python]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402

import sms3d_env  # noqa: E402, F401
from sms3d_env.controller import ControllerConfig  # noqa: E402


def measure(env_id: str, steps: int, image_obs: bool, n: int, pool: int = 0, substeps: int = ControllerConfig.substeps) -> tuple[float, float]:
    """Steps/s with random actions (the time limit's resets included) and the median reset time
    before the timed steps; ``pool`` > 0 draws beds from a pool of that many, every one of them
    generated and compiled before the timing (as in a long training run, whose envs have drawn
    each bed of their pool)."""
    # The mapping form: each version's own placement (v2: no two collision hulls interpenetrating).
    env = gym.make(env_id, scene={"config": {"placement": {"num_mushrooms": n}}, "pool": pool}, image_obs=image_obs,
                   controller=ControllerConfig(substeps=substeps))  # with its time limit
    env.reset(seed=0)
    source = env.unwrapped.scene_source
    while len(source.pool) < pool:
        env.reset()
    times = []
    for _ in range(max(3, pool)):
        t = time.perf_counter()
        env.reset()
        times.append(time.perf_counter() - t)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    t = time.perf_counter()
    for a in actions:
        *_, te, tr, _ = env.step(a)
        if te or tr:
            env.reset()
    rate = steps / (time.perf_counter() - t)
    env.close()
    return rate, statistics.median(times)


def fetch_rate(python: str) -> float:
    """FetchPickAndPlace-v4's steps/s, from bench_fetch.py run by ``python`` (its own venv)."""
    script = Path(__file__).with_name("bench_fetch.py")
    out = subprocess.run([python, str(script), "--steps", "2000"], capture_output=True, text=True, check=True).stdout
    return float(re.search(r": (\d+) steps/s", out).group(1))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--mushrooms", type=int, default=50)
    ap.add_argument("--resets", type=int, default=20)
    ap.add_argument("--version", choices=("v2", "v1"), default="v2")
    ap.add_argument("--substeps", type=int, default=ControllerConfig.substeps,
                    help="physics steps per 40 ms control step (ControllerConfig.substeps; default 10 x 4 ms)")
    ap.add_argument("--fetch-python", default=None,
                    help="a python with gymnasium-robotics (bench_fetch.py's venv): measure the anchor before and "
                         "after this run's rows and print the ratio")
    args = ap.parse_args()
    fetch = [fetch_rate(args.fetch_python)] if args.fetch_python else []
    env_id, train_id = f"SMS3DPick-{args.version}", f"SMS3DPickTrain-{args.version}"
    rows = []
    rate, reset_s = measure(env_id, args.steps, False, args.mushrooms, substeps=args.substeps)
    rows.append(("state obs", rate, reset_s))
    rate_p, reset_p = measure(env_id, args.steps, False, args.mushrooms, pool=8, substeps=args.substeps)
    rows.append(("state obs, 8-bed pool", rate_p, reset_p))
    rate_i, reset_i = measure(env_id, max(50, args.steps // 5), True, args.mushrooms, substeps=args.substeps)
    rows.append(("state + 64x64 RGB-D", rate_i, reset_i))
    if args.fetch_python:
        fetch.append(fetch_rate(args.fetch_python))

    ctrl = ControllerConfig(substeps=args.substeps)
    print(f"{env_id}, {args.mushrooms} mushrooms, {ctrl.control_dt * 1e3:.0f} ms/step ({ctrl.substeps} x "
          f"{ctrl.control_dt / ctrl.substeps * 1e3:g} ms), random actions, resets included")
    print(f"{'observation':<22}{'steps/s':>10}{'reset median (s)':>18}{'x Fetch':>9}")
    anchor = statistics.mean(fetch) if fetch else None
    for name, r, rs in rows:
        ratio = f"{r / anchor:>9.2f}" if anchor else ""
        print(f"{name:<22}{r:>10.0f}{rs:>18.3f}{ratio}")
    if anchor:
        print(f"anchor: FetchPickAndPlace-v4 (state) {fetch[0]:.0f} before, {fetch[1]:.0f} after this run's rows")
    else:
        print("anchor: FetchPickAndPlace-v4 (state); measure it here with --fetch-python or bench_fetch.py")
    sys.stdout.flush()
    print(f"\n{train_id} reset, {args.mushrooms} mushrooms, {args.resets} resets after a warm-up")
    print(f"{'beds':<34}{'reset (s)':>12}")
    for label, pool, kw in (("new bed per reset", 0, {}), ("pool of 8, target random", 8, {"target": "random"})):
        print(f"{label:<34}{reset_time(train_id, args.mushrooms, args.resets, pool, kw):>12.3f}")


def reset_time(env_id: str, n: int, resets: int, pool: int, kwargs: dict) -> float:
    """Mean reset time once a pool of ``pool`` beds (if any) is warm: each of its beds and targets
    seen once."""
    env = gym.make(env_id, scene={"config": {"placement": {"num_mushrooms": n}}, "pool": pool}, **kwargs)
    for s in range(3 * max(pool, 1)):
        env.reset(seed=s)
    t = time.perf_counter()
    for s in range(resets):
        env.reset(seed=1000 + s)
    env.close()
    return (time.perf_counter() - t) / resets


if __name__ == "__main__":
    main()
