"""The anchor for bench_env.py: FetchPickAndPlace-v4 steps/s with random actions, measured the
same way (state observations, reset on episode end, actions sampled before timing).

Gymnasium-Robotics needs mujoco < 3.12, so run this in its own environment, e.g.

    python -m venv /tmp/fetchenv && /tmp/fetchenv/bin/pip install gymnasium-robotics "mujoco<3.12"
    /tmp/fetchenv/bin/python benchmarks/bench_fetch.py --steps 2000

and, right after it on the same machine, ``python benchmarks/bench_env.py``.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--env", default="FetchPickAndPlace-v4")
    args = ap.parse_args()
    import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
    env = gym.make(args.env)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(args.steps)]
    start = time.perf_counter()
    for action in actions:
        *_, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    rate = args.steps / (time.perf_counter() - start)
    env.close()
    print(f"{args.env}: {rate:.0f} steps/s ({args.steps} random steps, state observations)")


if __name__ == "__main__":
    main()
