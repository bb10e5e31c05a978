"""Residual pick policies: a learned correction added to the scripted picker's command
(Silver et al. 2018, "Residual Policy Learning"; Johannink et al. 2019, "Residual Reinforcement
Learning for Robot Control").

``ResidualPicker`` wraps a pick env: the scripted picker (``ScriptedPicker.for_env``) runs inside
it on the same observation, the policy's action in [-1, 1]^7 is scaled by ``scale`` and added to
the picker's action, and the observation gains the picker's action (``base_action``) so that the
policy knows what it corrects. An all-zero residual is the scripted picker exactly, so training
starts from its success rate; PPO's action head starts near zero (orthogonal init, gain 0.01).
With ``until_held`` the residual corrects only the approach and touch-down: while the vacuum
sensor reports a seal (a hand: two fingers holding), the scripted picker's twist and lift run
alone, and the residual is back if the seal is lost (session 9: a residual over the whole episode lost grips the scripted picker kept).
With ``approach_only`` it corrects only the approach to the stand-off point: from the scripted
picker's descent on, its slow touch-down, twist and lift run alone (session 18: a residual until
held learned to descend about twice as fast, and at 30 deg of pose error 22 of 100 seals were
overloaded and lost within 1-3 steps of forming).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces


class ResidualPicker(gym.Wrapper):
    """``env`` driven by the scripted picker plus ``scale`` x the action.

    Args:
        env: a pick env (``SMS3DPick-v0`` or ``SMS3DPickTrain-v0``, any options).
        scale: the residual's largest share of each normalised command (0 < scale <= 2).
        until_held: drop the residual while ``obs["suction"][1]`` (sealed / holding) is set.
        approach_only: drop the residual once the scripted picker has left its approach phase
            (excludes ``until_held``, which it implies).
    """

    def __init__(self, env: gym.Env, scale: float = 0.5, until_held: bool = False,
                 approach_only: bool = False) -> None:
        super().__init__(env)
        if not (isinstance(scale, (int, float)) and np.isfinite(scale) and 0 < scale <= 2):
            raise ValueError(f"residual scale must be in (0, 2], got {scale!r}")
        from sms3d_env.pickers.scripted import ScriptedPicker

        if not isinstance(until_held, bool):
            raise ValueError(f"until_held must be a bool, got {until_held!r}")
        if not isinstance(approach_only, bool):
            raise ValueError(f"approach_only must be a bool, got {approach_only!r}")
        if approach_only and until_held:
            raise ValueError("approach_only already drops the residual before the seal; leave until_held False")
        self.scale = float(scale)
        self.until_held, self.approach_only = until_held, approach_only
        self.picker = ScriptedPicker.for_env(env)
        self.observation_space = spaces.Dict({
            **env.observation_space.spaces,
            "base_action": spaces.Box(-1.0, 1.0, (7,), np.float32)})
        self._base = np.zeros(7, np.float32)
        self._held = False
        self._base_phase = "approach"  # the scripted picker's phase that produced ``_base``

    def _with_base(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self._base_phase = self.picker.phase
        self._base = self.picker(obs)
        self._held = bool(obs["suction"][1] > 0.5)
        return {**obs, "base_action": self._base}

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self.picker.reset()
        return self._with_base(obs), info

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        if (self.until_held and self._held) or (self.approach_only and self._base_phase != "approach"):
            command = self._base
        else:
            a = np.asarray(action, np.float32)
            command = np.clip(self._base + self.scale * np.clip(a, -1.0, 1.0), -1.0, 1.0)
        obs, reward, terminated, truncated, info = self.env.step(command)
        return self._with_base(obs), reward, terminated, truncated, info
