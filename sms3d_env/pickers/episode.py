"""One seeded episode of any picker, summarised as the study's row."""

from __future__ import annotations

from typing import Any

import gymnasium as gym


def run_episode(env: gym.Env, policy: Any, seed: int, options: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run one episode; ``policy(obs) -> action`` (``policy.reset()`` is called if present)."""
    obs, info = env.reset(seed=seed, options=options)
    if hasattr(policy, "reset"):
        policy.reset()
    total, steps = 0.0, 0
    terminated = truncated = False
    while not (terminated or truncated):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total += float(reward)
        steps += 1
    return {
        "seed": seed, "success": bool(info["is_success"]), "failure_cause": info["failure_cause"],
        "reachable": bool(info["reachable"]), "target": int(info["target"]), "steps": steps,
        "return": total, "neighbours_disturbed": int(info["neighbours_disturbed"]),
        "bruised": bool(info["bruised"]), "target_detached": bool(info["target_detached"]),
        # Simulated seconds from reset to the episode's end (at success, the pick's cycle time),
        # and to the target's first grip and its detachment (None if they never happened).
        "time_s": float(info["time_s"]),
        "time_gripped_s": info["time_gripped_s"], "time_detached_s": info["time_detached_s"],
    }
