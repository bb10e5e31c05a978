"""Train a PPO pick policy on SMS3DPick-v0 (dense reward, 10 mushrooms) and evaluate it.

Usage: python examples/train_ppo.py [--steps 300000] [--n-envs 2] [--pose-error-deg 0] [--out runs/ppo]

Time here (2 shared CPU cores, no GPU): PPO with 2 SubprocVecEnv workers ran at about 240 env
steps/s (benchmarks/RESULTS.md, "Trained pick policies"), so the default 300k steps take about
20 minutes; the three 30-episode evaluations add one or two minutes.
Logs: <out>/progress.csv (eval/success_rate), checkpoints, <out>/model.zip.
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("MUJOCO_GL", "egl")

from sms3d_env.training import TrainConfig, evaluate_policy_success, train_policy  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=300_000)
    ap.add_argument("--n-envs", type=int, default=2)
    ap.add_argument("--pose-error-deg", type=float, default=0.0, help="train under this pose error")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--eval-episodes", type=int, default=30)
    ap.add_argument("--out", default="runs/ppo")
    args = ap.parse_args()
    cfg = TrainConfig(algo="ppo", total_steps=args.steps, n_envs=args.n_envs,
                      pose_source="noisy" if args.pose_error_deg > 0 else "oracle",
                      pose_error_deg=args.pose_error_deg, num_mushrooms=10, seed=args.seed,
                      out=args.out, eval_freq=25_000, eval_episodes=10)
    print(json.dumps(train_policy(cfg), indent=2))
    for err in (0.0, 10.0, 30.0):
        res = evaluate_policy_success(f"{args.out}/model.zip", episodes=args.eval_episodes,
                                      pose_error_deg=err, seed=1_000_000)
        lo, hi = res["ci95"]
        print(f"pose error {err:>4.0f} deg: success {res['success_rate']:.0%} "
              f"[{lo:.0%}, {hi:.0%}]  failures {res['failure_causes']}")


if __name__ == "__main__":
    main()
