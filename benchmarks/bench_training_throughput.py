"""PPO training throughput (env steps per wall second) of the from-scratch recipe for each way
of stepping the envs (``--vec-env``) and each observation layout (``--flat-observation``).

Each row trains the from-scratch recipe's PPO (``SMS3DPickTrain-v2``, observation normalisation,
pre-grasp starts, a rate falling over the wall clock, 2 envs, rollouts of 1024 steps per env)
for ``--steps`` env steps with no periodic evaluation or checkpoints, on a small scene pool (``--pool``) that the
first episodes fill, so that the rate is the steady one of a long run and not bed generation's.
The rate counts the whole ``train_policy`` call: worker start-up, rollouts and updates.

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

from sms3d_env.training import TrainConfig, train_policy  # noqa: E402

LAYOUTS = (("subproc", False), ("subproc", True), ("dummy", False), ("dummy", True))


def steps_per_s(vec_env: str, flat: bool, steps: int, pool: int, n_envs: int, out: str) -> float:
    cfg = TrainConfig(env_id="SMS3DPickTrain-v2", normalize=True, scene_pool=pool, n_envs=n_envs,
                      vec_env=vec_env, flat_observation=flat, num_mushrooms=10, pregrasp_start=0.75,
                      pregrasp_anneal=True, target_kl=0.02, log_std_init=-1.0, total_steps=steps,
                      eval_freq=0, checkpoint_freq=0, seed=0, out=out, verbose=0)
    t0 = time.perf_counter()
    train_policy(cfg)
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
