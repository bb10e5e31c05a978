"""Speed of SMS3DPick-v1 (or ``--version v0``): env steps/s with random actions and the
registered 250-step time limit, so the resets it triggers are in the rate (state observations,
50 mushrooms), reset time, and steps/s with 64 x 64 RGB-D observations; the training id's reset
with and without a scene pool. Anchor: FetchPickAndPlace-v4 (measure it beside this run with
bench_fetch.py).

Usage: python benchmarks/bench_env.py [--steps 500] [--version v1]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402

import generator  # noqa: E402
import sms3d_env  # noqa: E402, F401


def measure(env_id: str, steps: int, image_obs: bool, n: int, pool: int = 0) -> tuple[float, float]:
    """Steps/s with random actions (the time limit's resets included) and the mean time of the
    warm-up resets; ``pool`` > 0 draws beds from a pool of that many, each generated once in the
    warm-up (as a training run's envs do)."""
    from sms3d_env.scene_source import SceneSourceConfig

    cfg = generator.SceneConfig().replace(placement__num_mushrooms=n)
    env = gym.make(env_id, scene=SceneSourceConfig(config=cfg, pool=pool), image_obs=image_obs)  # with its time limit
    t = time.perf_counter()
    resets = max(3, pool)
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
    ap.add_argument("--resets", type=int, default=20)
    ap.add_argument("--version", choices=("v1", "v0"), default="v1")
    args = ap.parse_args()
    env_id, train_id = f"SMS3DPick-{args.version}", f"SMS3DPickTrain-{args.version}"
    rows = []
    rate, reset_s = measure(env_id, args.steps, False, args.mushrooms)
    rows.append(("state obs", rate, reset_s))
    rate_p, reset_p = measure(env_id, args.steps, False, args.mushrooms, pool=8)
    rows.append(("state obs, 8-bed pool", rate_p, reset_p))
    rate_i, reset_i = measure(env_id, max(50, args.steps // 5), True, args.mushrooms)
    rows.append(("state + 64x64 RGB-D", rate_i, reset_i))
    print(f"{env_id}, {args.mushrooms} mushrooms, 40 ms/step (20 x 2 ms), random actions, resets included")
    print(f"{'observation':<22}{'steps/s':>10}{'reset (s)':>12}")
    for name, r, rs in rows:
        print(f"{name:<22}{r:>10.0f}{rs:>12.3f}")
    print("anchor: FetchPickAndPlace-v4 (state); measure it here with bench_fetch.py")
    print(f"\n{train_id} reset, {args.mushrooms} mushrooms, {args.resets} resets after a warm-up")
    print(f"{'beds':<34}{'reset (s)':>12}")
    for label, pool, kw in (("new bed per reset", 0, {}), ("pool of 8, target random", 8, {"target": "random"})):
        print(f"{label:<34}{reset_time(train_id, args.mushrooms, args.resets, pool, kw):>12.3f}")


def reset_time(env_id: str, n: int, resets: int, pool: int, kwargs: dict) -> float:
    """Mean reset time once a pool of ``pool`` beds (if any) is warm: each of its beds and targets
    seen once."""
    from sms3d_env.scene_source import SceneSourceConfig

    cfg = generator.SceneConfig().replace(placement__num_mushrooms=n)
    env = gym.make(env_id, scene=SceneSourceConfig(config=cfg, pool=pool), **kwargs)
    for s in range(3 * max(pool, 1)):
        env.reset(seed=s)
    t = time.perf_counter()
    for s in range(resets):
        env.reset(seed=1000 + s)
    env.close()
    return (time.perf_counter() - t) / resets


if __name__ == "__main__":
    main()
