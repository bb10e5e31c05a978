"""Residual pick policies: a learned correction added to the scripted picker's command
(Silver et al. 2018, "Residual Policy Learning"; Johannink et al. 2019, "Residual Reinforcement
Learning for Robot Control").

``ResidualPicker`` wraps a pick env: the scripted picker (``ScriptedPicker.for_env``) runs inside
it on the same observation, the policy's action in [-1, 1]^7 (its first 7 entries with
``descend_trigger``) is scaled by ``scale`` and added to
the picker's action, and the observation gains the picker's action (``base_action``) so that the
policy knows what it corrects. An all-zero residual is the scripted picker exactly, so training
starts from its success rate; PPO's action head starts near zero (orthogonal init, gain 0.01).
With ``descend_trigger`` the action gains an eighth entry: above :data:`DESCEND_TRIGGER` while
the scripted picker approaches and its tool is within :data:`DESCEND_TRIGGER_RADIUS_M` of the
stand-off point, it starts the descent from where the tool is (measured: under 20-30 deg of pose
error the scripted approach stalls short of its 3 mm / 3 deg tolerance, and a hand-written escape
from such stalls won 7 of 100 paired episodes at 20 deg; the trigger lets the policy learn when
to give up on the approach, from what it sees: joint velocities, its command, the tool offset).
With ``trigger_only`` the action is the trigger alone: the scripted picker's command runs
unchanged and the policy decides only when its approach gives way to the descent (measured: the
residual's seven continuous entries changed trajectories in every episode, and their noise swapped
about as many picks each way as the trigger won at 30 deg).
A policy whose trigger entry has mean 0 (an untrained one, run deterministically) never fires
it (the shipped trigger is learned from paired rollouts, :mod:`sms3d_env.training.trigger_rollouts`).
With the trigger the observation also gains ``approach_motion``: the tool's distance from the
stand-off point and how far the tool moved over the last :data:`MOTION_WINDOW_STEPS` control
steps (measured: a trigger that saw only this step's joint velocities learned to cut approaches
short 5-20 mm out rather than to detect a stall, which is "commanding motion and not moving over
0.4 s"). Both come from the arm's forward kinematics and the estimated pose, as on a real robot.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

#: The trigger entry's value above which the descent starts (actions are in [-1, 1]).
DESCEND_TRIGGER = 0.5
#: How near the stand-off point (m) the trigger acts: the radius of the hand-written stall escape
#: that won 7 of 100 paired episodes at 20 deg (``benchmarks/bench_tolerance_headroom.py``).
DESCEND_TRIGGER_RADIUS_M = 0.02
#: The trigger's index in the action: the last entry (after the residual's seven, or alone).
DESCEND_TRIGGER_ENTRY = -1
#: Control steps over which ``approach_motion`` measures the tool's displacement: the hand-written
#: stall escape's window (0.4 s at the env's 25 Hz control).
MOTION_WINDOW_STEPS = 10


class ResidualPicker(gym.Wrapper):
    """``env`` driven by the scripted picker plus ``scale`` x the action.

    Args:
        env: a pick env (``SMS3DPick-v0`` or ``SMS3DPickTrain-v0``, any options).
        scale: the residual's largest share of each normalised command (0 < scale <= 2).
        descend_trigger: an eighth action entry that starts the descent near the stand-off point
            (``info["descend_triggered"]`` is set on the step it does). The descent's travel
            limit grows by the tool's distance from the stand-off point. The observation gains
            ``approach_motion (2,)``: the tool's distance from the stand-off point (m) and its
            displacement over the last :data:`MOTION_WINDOW_STEPS` control steps (m; since
            the reset while fewer steps have run).
        trigger_only: the action is the trigger alone; the scripted picker's command runs
            unchanged (needs ``descend_trigger``).
    """

    def __init__(self, env: gym.Env, scale: float = 0.5, descend_trigger: bool = False,
                 trigger_only: bool = False) -> None:
        super().__init__(env)
        if not (isinstance(scale, (int, float)) and np.isfinite(scale) and 0 < scale <= 2):
            raise ValueError(f"residual scale must be in (0, 2], got {scale!r}")
        from sms3d_env.pickers.scripted import ScriptedPicker

        if not isinstance(descend_trigger, bool):
            raise ValueError(f"descend_trigger must be a bool, got {descend_trigger!r}")
        if not isinstance(trigger_only, bool):
            raise ValueError(f"trigger_only must be a bool, got {trigger_only!r}")
        if trigger_only and not descend_trigger:
            raise ValueError("trigger_only keeps only the descend trigger; set descend_trigger=True")
        self.scale = float(scale)
        self.descend_trigger = descend_trigger
        self.trigger_only = trigger_only
        self.picker = ScriptedPicker.for_env(env)
        extra = {"base_action": spaces.Box(-1.0, 1.0, (7,), np.float32)}
        if descend_trigger:
            self.action_space = spaces.Box(-1.0, 1.0, (1 if trigger_only else 8,), np.float32)
            extra["approach_motion"] = spaces.Box(0.0, np.inf, (2,), np.float32)
        self.observation_space = spaces.Dict({**env.observation_space.spaces, **extra})
        self._tool_trail: deque[np.ndarray] = deque(maxlen=MOTION_WINDOW_STEPS + 1)
        self._base = np.zeros(7, np.float32)
        self._standoff_gap = 0.0  # m, from the tool to the stand-off point

    def _with_base(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        extra = {}
        if self.descend_trigger:  # the gap and the motion are read only by the trigger
            view = self.picker.view(obs)
            self._standoff_gap = float(np.linalg.norm(self.picker.approach_goal(view) - view.p))
            self._tool_trail.append(np.array(view.p, np.float64))
            moved = float(np.linalg.norm(self._tool_trail[-1] - self._tool_trail[0]))
            extra["approach_motion"] = np.array([self._standoff_gap, moved], np.float32)
        self._base = self.picker(obs)
        return {**obs, "base_action": self._base, **extra}

    @property
    def trigger_can_fire(self) -> bool:
        """Whether the descend trigger acts on the next step: the scripted picker approaches and
        the tool is within :data:`DESCEND_TRIGGER_RADIUS_M` of the stand-off point."""
        return (self.descend_trigger and self.picker.phase == "approach"
                and self._standoff_gap < DESCEND_TRIGGER_RADIUS_M)

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self.picker.reset()
        self._tool_trail.clear()
        return self._with_base(obs), info

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        a = np.asarray(action, np.float32)
        if a.shape != self.action_space.shape:
            raise ValueError(f"action of shape {a.shape} for a residual whose action space is "
                             f"{self.action_space.shape} (descend_trigger={self.descend_trigger}, "
                             f"trigger_only={self.trigger_only})")
        if self.trigger_only:
            command = self._base
        else:
            command = np.clip(self._base + self.scale * np.clip(a[:7], -1.0, 1.0), -1.0, 1.0)
        triggered = self.trigger_can_fire and a[DESCEND_TRIGGER_ENTRY] > DESCEND_TRIGGER
        if triggered:  # the next command is the descent's, from where the tool is
            self.picker.phase = "descend"
            # Its travel limit (stand-off + 2 cm, then lift) counts from the stand-off point.
            self.picker.descended = -self._standoff_gap
        obs, reward, terminated, truncated, info = self.env.step(command)
        if self.descend_trigger:
            info["descend_triggered"] = bool(triggered)
        return self._with_base(obs), reward, terminated, truncated, info

