"""PPO training throughput (env steps per wall second) of the from-scratch recipe for each way
of stepping the envs (``--vec-env``) and each observation layout (the recipe's flattened one, or
the dict observation with ``MultiInputPolicy``).

Each row trains the shipped ``ppo`` recipe with RL Zoo's trainer (``SMS3DPickTrain-v2``,
normalisation, pre-grasp starts, a rate falling over the wall clock, rollouts of 1024 steps per
env) for ``--steps`` env steps with no periodic evaluation or checkpoints, on a small scene pool
(``--pool``) that the first episodes fill, so that the rate is the steady one of a long run and
not bed generation's. The rate counts the whole training call: worker start-up, rollouts and
updates.

Usage: python benchmarks/bench_training_throughput.py [--steps 32768] [--pool 16] [--n-envs 2]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # runs from a checkout

from sms3d_env.training.recipes import read_recipe  # noqa: E402
from sms3d_env.training.zoo import train_zoo, zoo_argv  # noqa: E402

LAYOUTS = (("subproc", False), ("subproc", True), ("dummy", False), ("dummy", True))


def steps_per_s(vec_env: str, flat: bool, steps: int, pool: int, n_envs: int, out: str) -> float:
    env_kwargs = dict(read_recipe("ppo").config["env_kwargs"])
    env_kwargs["scene"] = {**env_kwargs["scene"], "pool": pool}
    layout = {} if flat else {"env_wrapper": None, "policy": "MultiInputPolicy"}
    argv = zoo_argv("ppo", out=out, steps=steps, n_envs=n_envs, vec_env=vec_env, eval_freq=0,
                    hyperparams={"env_kwargs": env_kwargs, **layout})
    t0 = time.perf_counter()
    train_zoo(argv)
    return steps / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=32768, help="env steps per row")
    p.add_argument("--pool", type=int, default=16, help="beds in the scene pool")
    p.add_argument("--n-envs", type=int, default=2)
    args = p.parse_args()
    print(f"| --vec-env | observation | steps/s ({args.steps} steps, {args.n_envs} envs, {args.pool}-bed pool) |")
    print("| --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for vec_env, flat in LAYOUTS:
            rate = steps_per_s(vec_env, flat, args.steps, args.pool, args.n_envs, str(Path(tmp) / f"{vec_env}{flat}"))
            print(f"| {vec_env} | {'flat (MlpPolicy)' if flat else 'dict (MultiInputPolicy)'} | {rate:.0f} |", flush=True)


if __name__ == "__main__":
    main()
