"""How much of PPO's clipped gradient step the value loss takes from the policy, per checkpoint.

SB3's PPO clips the norm of the *whole* gradient (policy loss + ``vf_coef`` × value loss, every
parameter) at ``max_grad_norm`` (0.5). The policy and value networks are separate, so the policy's
share of a clipped step is ``min(1, 0.5 / total norm)`` of its own gradient: a large value loss
shrinks the policy's step. For each checkpoint this collects one rollout (``n_steps`` per env,
the run's envs and observation statistics, fresh env seeds) and, for each minibatch of it,
computes the norms of the policy loss's and the value loss's gradients apart and the factor the
clip puts on the policy's step. Returns are in the units the critic learns: the env's rewards,
or with ``--normalize-reward`` the rewards scaled by the checkpoint's return statistics.

Usage: python benchmarks/bench_ppo_gradient_share.py RUN_DIR --steps 300000 1200000 [--seed 123]
(RUN_DIR a ``sms3d train-policy`` PPO run with ``--normalize`` and checkpoints.)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # runs from a checkout

import numpy as np  # noqa: E402
import torch  # noqa: E402

from sms3d_env.policies.files import ObservationStats  # noqa: E402
from sms3d_env.policies.loader import observation_stats_path  # noqa: E402
from sms3d_env.training import TrainConfig  # noqa: E402
from sms3d_env.training.envs import vec_env  # noqa: E402


def _grad_norm(model: torch.nn.Module, loss: torch.Tensor) -> float:
    model.zero_grad()
    loss.backward(retain_graph=True)
    return float(torch.sqrt(sum((p.grad**2).sum() for p in model.parameters() if p.grad is not None)))


def gradient_share(run: Path, steps: int, seed: int) -> dict[str, float]:
    """One rollout of the checkpoint at ``steps``: its returns and, over its minibatches, the
    median policy- and value-gradient norms and the clip factor on the policy's step."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    cfg = TrainConfig.from_dict(json.loads((run / "config.json").read_text()))
    checkpoint = run / "checkpoints" / f"ppo_{steps}_steps.zip"
    stats = observation_stats_path(checkpoint)
    if cfg.algo != "ppo" or stats is None:
        raise SystemExit(f"{checkpoint}: needs a PPO checkpoint of a run trained with --normalize")
    env = vec_env(cfg.env_kwargs(), cfg.n_envs, seed, None, "dummy")
    env = VecNormalize(env, training=False, norm_reward=False)  # the checkpoint's statistics, as they were
    ObservationStats.load(stats).apply_to(env)
    model = PPO.load(str(checkpoint), env=env, device="cpu")

    class _Continue(BaseCallback):
        def _on_step(self) -> bool:
            return True

    callback = _Continue()
    callback.init_callback(model)
    model._setup_learn(model.n_steps * cfg.n_envs, None)
    model.collect_rollouts(env, callback, model.rollout_buffer, n_rollout_steps=model.n_steps)
    env.close()
    rows = []
    clip = float(model.clip_range(1.0))
    for batch in model.rollout_buffer.get(model.batch_size):
        values, log_prob, _ = model.policy.evaluate_actions(batch.observations, batch.actions)
        adv = (batch.advantages - batch.advantages.mean()) / (batch.advantages.std() + 1e-8)
        ratio = torch.exp(log_prob - batch.old_log_prob)
        policy_loss = -torch.min(adv * ratio, adv * torch.clamp(ratio, 1 - clip, 1 + clip)).mean()
        value_loss = torch.nn.functional.mse_loss(batch.returns, values.flatten())
        g_policy = _grad_norm(model.policy, policy_loss)
        g_value = _grad_norm(model.policy, model.vf_coef * value_loss)
        rows.append((value_loss.item(), g_policy, g_value, min(1.0, model.max_grad_norm / np.hypot(g_policy, g_value))))
    r = np.array(rows)
    returns = model.rollout_buffer.returns
    return {"steps": steps, "max_return": float(returns.max()), "value_loss": float(np.median(r[:, 0])),
            "policy_grad": float(np.median(r[:, 1])), "value_grad": float(np.median(r[:, 2])),
            "policy_clip_factor": float(np.median(r[:, 3])),
            "policy_only_factor": float(np.median(np.minimum(1.0, model.max_grad_norm / r[:, 1])))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path, help="a PPO run folder (config.json, checkpoints/)")
    parser.add_argument("--steps", type=int, nargs="+", required=True, help="checkpoints (env steps)")
    parser.add_argument("--seed", type=int, default=123, help="env seeds of the rollout (seed + i)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print("| checkpoint | largest return in the rollout | value loss | policy grad norm | value grad norm | "
          "clip factor on the policy step | without the value loss |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for steps in args.steps:
        s = gradient_share(args.run, steps, args.seed)
        print(f"| {s['steps']:,} | {s['max_return']:.0f} | {s['value_loss']:.2f} | {s['policy_grad']:.2f} | "
              f"{s['value_grad']:.2f} | {s['policy_clip_factor']:.3f} | {s['policy_only_factor']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
