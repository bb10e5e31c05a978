"""Train a pick policy from a shipped recipe with the Python API, then evaluate it with exact poses
and under 10 and 30 degrees of orientation error (held-out beds).

Usage: python examples/train_policy.py [--recipe pick_policy|ppo] [--seed 0] [--out DIR]

The same as ``sms3d train-policy RECIPE --out DIR`` followed by ``sms3d eval-policy``. Time here
(2 CPU cores, no GPU): ``pick_policy`` (behaviour cloning + DAgger) about 500 s, a run folder that
a rerun with the same settings resumes; ``ppo`` (PPO from scratch with RL Baselines3 Zoo's trainer)
the recipe's 2,400 s, into RL Zoo's run folder DIR/ppo/SMS3DPickTrain-v2_N.
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("MUJOCO_GL", "egl")

from sms3d_env.training import evaluate_policy_success, read_recipe, train_bc, train_zoo, zoo_argv  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--recipe", default="pick_policy", help="a shipped recipe (pick_policy, ppo) or a recipe file")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--eval-episodes", type=int, default=30)
    ap.add_argument("--out", help="run folder (default runs/<recipe>)")
    args = ap.parse_args()
    recipe = read_recipe(args.recipe)
    out = args.out or f"runs/{os.path.splitext(os.path.basename(args.recipe))[0]}"
    if recipe.kind == "bc":
        summary = train_bc(recipe.with_fields({"out": out, "seed": args.seed}, "examples/train_policy.py").config)
    else:
        summary = train_zoo(zoo_argv(recipe.source, out=out, seed=args.seed))
    print(json.dumps(summary, indent=2))
    for err in (0.0, 10.0, 30.0):
        res = evaluate_policy_success(summary["model"], episodes=args.eval_episodes,
                                      pose_error_deg=err, seed=1_000_000)
        lo, hi = res["ci95"]
        print(f"pose error {err:>4.0f} deg: success {res['success_rate']:.0%} "
              f"[{lo:.0%}, {hi:.0%}]  failures {res['failure_causes']}")


if __name__ == "__main__":
    main()
