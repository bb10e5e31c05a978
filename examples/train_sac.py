"""Train a SAC pick policy on SMS3DPick-v0 (dense reward, 10 mushrooms) and evaluate it.

Usage: python examples/train_sac.py [--steps 20000] [--n-envs 1] [--pose-error-deg 0] [--out runs/sac]

Time here (2 shared CPU cores, no GPU, alongside a PPO run): SAC does one gradient step per
env step, so it is slower per step than PPO: about 23 env steps/s overall in a 90 s run with
1 env (1,000 random steps, then ~13 steps/s once updates start), so the default 20k steps take
roughly 25 minutes.
Each 30-episode evaluation adds about a minute or two.
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
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--n-envs", type=int, default=1)
    ap.add_argument("--pose-error-deg", type=float, default=0.0, help="train under this pose error")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--eval-episodes", type=int, default=30)
    ap.add_argument("--out", default="runs/sac")
    args = ap.parse_args()
    cfg = TrainConfig(algo="sac", total_steps=args.steps, n_envs=args.n_envs,
                      pose_source="noisy" if args.pose_error_deg > 0 else "oracle",
                      pose_error_deg=args.pose_error_deg, num_mushrooms=10, seed=args.seed,
                      out=args.out, eval_freq=5_000, eval_episodes=10, learning_starts=1_000)
    print(json.dumps(train_policy(cfg), indent=2))
    for err in (0.0, 10.0, 30.0):
        res = evaluate_policy_success(f"{args.out}/model.zip", episodes=args.eval_episodes,
                                      pose_error_deg=err, seed=1_000_000)
        lo, hi = res["ci95"]
        print(f"pose error {err:>4.0f} deg: success {res['success_rate']:.0%} "
              f"[{lo:.0%}, {hi:.0%}]  failures {res['failure_causes']}")


if __name__ == "__main__":
    main()
