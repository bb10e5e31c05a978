"""Residual pick policies: a learned correction added to the scripted picker's command
(Silver et al. 2018, "Residual Policy Learning"; Johannink et al. 2019, "Residual Reinforcement
Learning for Robot Control").

``ResidualPicker`` wraps a pick env: the scripted picker (``ScriptedPicker.for_env``) runs inside
it on the same observation, the policy's action in [-1, 1]^7 (its first 7 entries with
``descend_trigger``) is scaled by ``scale`` and added to
the picker's action, and the observation gains the picker's action (``base_action``) so that the
policy knows what it corrects. An all-zero residual is the scripted picker exactly, so training
starts from its success rate; PPO's action head starts near zero (orthogonal init, gain 0.01).
With ``until_held`` the residual corrects only the approach and touch-down: while the vacuum
sensor reports a seal (a hand: two fingers holding), the scripted picker's twist and lift run
alone, and the residual is back if the seal is lost (measured: a residual over the whole
episode lost grips the scripted picker kept).
With ``approach_only`` it corrects only the approach to the stand-off point: from the scripted
picker's descent on, its slow touch-down, twist and lift run alone (measured: a residual until
held learned to descend about twice as fast, and at 30 deg of pose error 22 of 100 seals were
overloaded and lost within 1-3 steps of forming).
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
it; in training PPO explores it with its own, wider noise (:data:`DESCEND_TRIGGER_LOG_STD_INIT`).
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
#: PPO's initial log standard deviation of the trigger entry (sigma 0.4: above the threshold on
#: about 11 % of steps). The residual's own entries start at -1.6 (sigma 0.2), where the trigger
#: would fire on 0.6 % of steps and a stall would rarely be escaped often enough to learn from;
#: a deterministic policy (the mean, 0 at the start) never fires it until it has learned to.
#: Measured: at 0.4 a stochastic policy escapes every stall by chance within a few steps, so
#: firing at once in a stall earns little and the mean stays below the threshold; ``sms3d
#: train-policy --trigger-log-std`` sets it lower.
DESCEND_TRIGGER_LOG_STD_INIT = -0.9
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
        until_held: drop the residual while ``obs["suction"][1]`` (sealed / holding) is set.
        approach_only: drop the residual once the scripted picker has left its approach phase
            (excludes ``until_held``, which it implies).
        descend_trigger: an eighth action entry that starts the descent near the stand-off point
            (``info["descend_triggered"]`` is set on the step it does). The descent's travel
            limit grows by the tool's distance from the stand-off point. The observation gains
            ``approach_motion (2,)``: the tool's distance from the stand-off point (m) and its
            displacement over the last :data:`MOTION_WINDOW_STEPS` control steps (m; since
            the reset while fewer steps have run).
    """

    def __init__(self, env: gym.Env, scale: float = 0.5, until_held: bool = False,
                 approach_only: bool = False, descend_trigger: bool = False, trigger_only: bool = False) -> None:
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
        if not isinstance(descend_trigger, bool):
            raise ValueError(f"descend_trigger must be a bool, got {descend_trigger!r}")
        if not isinstance(trigger_only, bool):
            raise ValueError(f"trigger_only must be a bool, got {trigger_only!r}")
        if trigger_only and not descend_trigger:
            raise ValueError("trigger_only keeps only the descend trigger; set descend_trigger=True")
        if trigger_only and (until_held or approach_only):
            raise ValueError("trigger_only has no continuous residual for until_held/approach_only to limit")
        self.scale = float(scale)
        self.until_held, self.approach_only, self.descend_trigger = until_held, approach_only, descend_trigger
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
        self._held = False
        self._base_phase = "approach"  # the scripted picker's phase that produced ``_base``

    def _with_base(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self._base_phase = self.picker.phase
        extra = {}
        if self.descend_trigger:  # the gap and the motion are read only by the trigger
            view = self.picker.view(obs)
            self._standoff_gap = float(np.linalg.norm(self.picker.approach_goal(view) - view.p))
            self._tool_trail.append(np.array(view.p, np.float64))
            moved = float(np.linalg.norm(self._tool_trail[-1] - self._tool_trail[0]))
            extra["approach_motion"] = np.array([self._standoff_gap, moved], np.float32)
        self._base = self.picker(obs)
        self._held = bool(obs["suction"][1] > 0.5)
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
        if (self.trigger_only or (self.until_held and self._held)
                or (self.approach_only and self._base_phase != "approach")):
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


def set_trigger_log_std(policy: Any, log_std: float) -> None:
    """Set the exploration log standard deviation of a PPO ``policy``'s trigger entry (the
    residual's entries keep theirs); with gSDE (``use_sde``) that of every weight of the
    trigger's noise map."""
    import torch

    with torch.no_grad():
        policy.log_std[..., DESCEND_TRIGGER_ENTRY] = log_std
