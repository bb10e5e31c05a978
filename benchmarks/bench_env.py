"""Speed of SMS3DPick-v0: env steps/s (state observations, 50 mushrooms), reset time, and
steps/s with 64 x 64 RGB-D observations. Anchor: FetchPickAndPlace-v4 ~1,100 steps/s here
(measure it beside this run with bench_fetch.py).

Usage: python benchmarks/bench_env.py [--steps 500]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402

import generator  # noqa: E402
import sms3d_env  # noqa: E402, F401


def measure(steps: int, image_obs: bool, n: int) -> tuple[float, float]:
    cfg = generator.SceneConfig().replace(placement__num_mushrooms=n)
    env = gym.make("SMS3DPick-v0", scene_config=cfg, image_obs=image_obs).unwrapped
    t = time.perf_counter()
    resets = 3
    for s in range(resets):
        env.reset(seed=s)
    reset_s = (time.perf_counter() - t) / resets
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    t = time.perf_counter()
    for a in actions:
        *_, te, tr, _ = env.step(a)
        if te or tr:
            env.reset()
    rate = steps / (time.perf_counter() - t)
    env.close()
    return rate, reset_s


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--mushrooms", type=int, default=50)
    args = ap.parse_args()
    rows = []
    rate, reset_s = measure(args.steps, False, args.mushrooms)
    rows.append(("state obs", rate, reset_s))
    rate_i, reset_i = measure(max(50, args.steps // 5), True, args.mushrooms)
    rows.append(("state + 64x64 RGB-D", rate_i, reset_i))
    print(f"SMS3DPick-v0, {args.mushrooms} mushrooms, 40 ms/step (20 x 2 ms), random actions")
    print(f"{'observation':<22}{'steps/s':>10}{'reset (s)':>12}")
    for name, r, rs in rows:
        print(f"{name:<22}{r:>10.0f}{rs:>12.3f}")
    print("anchor: FetchPickAndPlace-v4 ~1,100 steps/s (state); measure it here with bench_fetch.py")


if __name__ == "__main__":
    main()
