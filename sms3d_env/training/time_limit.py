"""The time limit as the end of the task rather than an interruption of it.

Gymnasium's ``TimeLimit`` reports the 250th step as *truncated*, and SB3 then bootstraps the
return there with the critic's value of the last observation, as if the episode could go on.
That is right for a policy that cannot see the clock, but the learnable options observe the
time since the reset (``progress[0]``), so the limit is part of the task the policy solves, and
the step that reaches it ends the episode (Pardo et al. 2018, "Time Limits in Reinforcement
Learning", ICML: for a time-aware agent the limit is a terminal state). Bootstrapped there, an
approach that stalls until the limit is valued like the stalled states before it, which are
escaped by chance during training: waiting costs the critic nothing, and the residual's descend
trigger has no reason to fire in a stall.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym


class TimeLimitAsTerminal(gym.Wrapper):
    """``env`` with the step that reaches its registered time limit reported as terminated
    (``info["time_limit_reached"]`` set), not truncated. The pick env truncates nothing but an
    unstable simulation (``info["unstable_simulation"]``), which stays a truncation, so any other
    truncation is the ``TimeLimit``'s.

    Args:
        env: an env made by ``gym.make`` with a time limit (``env.spec.max_episode_steps``).
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        if env.spec is None or env.spec.max_episode_steps is None:
            raise ValueError("TimeLimitAsTerminal needs an env made with a time limit "
                             "(gym.make(..., max_episode_steps=N)); this one has none")

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if truncated and not terminated and not info.get("unstable_simulation", False):
            terminated, truncated = True, False
            info = {**info, "time_limit_reached": True}
        return obs, reward, terminated, truncated, info
