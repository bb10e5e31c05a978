"""Train a PPO or SAC pick policy on SMS3DPick-v0 (dense reward, 10 mushrooms) and evaluate it
with exact poses and under 10 and 30 degrees of pose error.

Usage: python examples/train_policy.py --algo ppo|sac [--steps N] [--n-envs K] [--pose-error-deg 0] [--out DIR]

Time here (2 shared CPU cores, no GPU; measured in benchmarks/RESULTS.md, the measurement log):
PPO with 2 SubprocVecEnv workers runs at about 240-370 env steps/s, so its default 300k steps
take about 20 minutes. SAC does a gradient step per env step: about 13 env steps/s once updates
start, so its default 20k steps take about 25 minutes. Each 30-episode evaluation adds a minute
or two. Logs: <out>/progress.csv (eval/success_rate), checkpoints, <out>/model.zip.
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("MUJOCO_GL", "egl")

from sms3d_env.training import TrainConfig, evaluate_policy_success, train_policy  # noqa: E402

DEFAULTS = {  # per algorithm: steps, envs, evaluation period, extra TrainConfig fields
    "ppo": (300_000, 2, 25_000, {}),
    "sac": (20_000, 1, 5_000, {"learning_starts": 1_000}),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--algo", choices=sorted(DEFAULTS), default="ppo")
    ap.add_argument("--steps", type=int, help="env steps (default: 300k for PPO, 20k for SAC)")
    ap.add_argument("--n-envs", type=int, help="parallel envs (default: 2 for PPO, 1 for SAC)")
    ap.add_argument("--pose-error-deg", type=float, default=0.0, help="train under this pose error")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--eval-episodes", type=int, default=30)
    ap.add_argument("--out", help="run folder (default runs/<algo>)")
    args = ap.parse_args()
    steps, n_envs, eval_freq, extra = DEFAULTS[args.algo]
    out = args.out or f"runs/{args.algo}"
    cfg = TrainConfig(algo=args.algo, total_steps=args.steps or steps, n_envs=args.n_envs or n_envs,
                      pose_source="noisy" if args.pose_error_deg > 0 else "oracle",
                      pose_error_deg=args.pose_error_deg, num_mushrooms=10, seed=args.seed,
                      out=out, eval_freq=eval_freq, eval_episodes=10, **extra)
    print(json.dumps(train_policy(cfg), indent=2))
    for err in (0.0, 10.0, 30.0):
        res = evaluate_policy_success(f"{out}/model.zip", episodes=args.eval_episodes,
                                      pose_error_deg=err, seed=1_000_000)
        lo, hi = res["ci95"]
        print(f"pose error {err:>4.0f} deg: success {res['success_rate']:.0%} "
              f"[{lo:.0%}, {hi:.0%}]  failures {res['failure_causes']}")


if __name__ == "__main__":
    main()
