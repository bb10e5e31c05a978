"""Scripted pose-aware picker: the baseline policy, driven only by the observation.

Phases: approach a stand-off point above the *estimated* cap top along the estimated stem axis
with the cup facing down the axis; descend along the axis with suction on until the cup seals;
twist about the estimated stem axis ("twist, do not pull", optionally with a gentle bend); lift
straight up. A wrong estimate tilts the cup against the cap (no seal, or a contact off the cap
top) and twists about the wrong axis, which bends the root and the seal.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


def _quat_to_mat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


class ScriptedPicker:
    """Approach, seal, twist (with a gentle bend), lift. Call ``reset()`` at each episode start.

    Phases, all along the *estimated* pose from the observation:

    1. ``approach``: move to a stand-off point above the estimated cap top on the estimated stem
       axis, the cup facing down that axis;
    2. ``descend``: move down the axis with suction on until the cup seals (or give up);
    3. ``twist``: rotate about the estimated stem axis through the cup ("twist, do not pull"),
       with a slight pull along the axis and an optional gentle bend about the estimated stem
       base; a wrong axis turns part of the twist into bending of the root and the seal;
    4. ``lift``: straight up, the speed ramped up (no jerk on the seal).

    Args:
        max_linear_speed, max_angular_speed: the env's action scales (m/s, rad/s).
        standoff: approach point above the estimated cap top along the axis (m).
        stem_height: assumed cap-top-to-stem-base distance for the bend pivot (m).
        descend_speed: approach speed along the axis once at the stand-off point (m/s).
        twist_rate: rad/s about the estimated axis during ``twist_steps`` control steps.
        bend_rate: rad/s of gentle bend (about a horizontal axis, pivot at the estimated stem base).
        pull_speed: slight withdrawal along the axis while twisting (m/s).
        lift_speed, lift_ramp_steps: lift speed (m/s), reached linearly over this many steps.
        settle_steps: still steps after the seal forms (the arm stops pressing).
    """

    def __init__(self, max_linear_speed: float = 0.12, max_angular_speed: float = 0.8,
                 control_dt: float = 0.04, standoff: float = 0.03, stem_height: float = 0.04,
                 descend_speed: float = 0.02, twist_rate: float = 0.8, bend_rate: float = 0.0,
                 twist_steps: int = 30, pull_speed: float = 0.002, settle_steps: int = 2,
                 lift_speed: float = 0.06, lift_ramp_steps: int = 5) -> None:
        self.vmax, self.wmax, self.dt = max_linear_speed, max_angular_speed, control_dt
        self.standoff, self.stem_height = standoff, stem_height
        self.descend_speed, self.bend_rate, self.twist_rate = descend_speed, bend_rate, twist_rate
        self.twist_steps, self.pull_speed, self.settle_steps = twist_steps, pull_speed, settle_steps
        self.lift_speed, self.lift_ramp_steps = lift_speed, lift_ramp_steps
        self.reset()

    @classmethod
    def for_env(cls, env: gym.Env, **kwargs: Any) -> ScriptedPicker:
        u = env.unwrapped
        return cls(u.ctrl_cfg.max_linear_speed, u.ctrl_cfg.max_angular_speed, u.control_dt, **kwargs)

    def reset(self) -> None:
        self.phase = "approach"
        self.count = 0
        self.descended = 0.0
        self.lift_count = 0

    def _action(self, v: np.ndarray, w: np.ndarray, suction: bool) -> np.ndarray:
        a = np.concatenate([v / self.vmax, w / self.wmax, [1.0 if suction else -1.0]])
        return np.clip(a, -1, 1).astype(np.float32)

    def __call__(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        p = obs["tool_pose"][:3]
        z = _quat_to_mat(obs["tool_pose"][3:])[:, 2]
        c, axis = obs["target_pose"][:3], obs["target_pose"][3:]
        axis = axis / np.linalg.norm(axis)
        w_align = 3.0 * np.cross(z, -axis)
        gripped = obs["suction"][1] > 0.5
        if self.phase == "approach":
            goal = c + axis * self.standoff
            err = goal - p
            ang = np.degrees(np.arccos(np.clip(z @ -axis, -1, 1)))
            if np.linalg.norm(err) < 0.003 and ang < 3.0:
                self.phase = "descend"
            # Proportional, at least 2 cm/s until the tolerance (no slow creep near the goal).
            n_err = np.linalg.norm(err)
            speed = min(self.vmax, max(4.0 * n_err, 0.02))
            v = err / max(n_err, 1e-9) * speed
            return self._action(v, w_align, False)
        if self.phase == "descend":
            if gripped:
                self.phase, self.count = "settle", 0
                return self._action(np.zeros(3), np.zeros(3), True)
            self.descended += self.descend_speed * self.dt
            if self.descended > self.standoff + 0.02:
                self.phase = "lift"
            rel = p - c
            lateral = rel - (rel @ axis) * axis
            v = -axis * self.descend_speed - 4.0 * lateral
            return self._action(v, w_align, True)
        if self.phase == "settle":
            self.count += 1
            if self.count >= self.settle_steps:
                self.phase, self.count = "twist", 0
            return self._action(np.zeros(3), np.zeros(3), True)
        if self.phase == "twist":
            self.count += 1
            if self.count >= self.twist_steps:
                self.phase = "lift"
            w = self.twist_rate * axis
            v = self.pull_speed * axis
            if self.bend_rate > 0:
                horiz = np.array([axis[0], axis[1], 0.0])
                if np.linalg.norm(horiz) < 0.05:
                    horiz = np.array([1.0, 0.0, 0.0])
                bend_axis = np.cross(np.array([0.0, 0.0, 1.0]), horiz)
                bend_axis /= np.linalg.norm(bend_axis)
                wb = self.bend_rate * bend_axis
                w = w + wb
                v = v + np.cross(wb, p - (c - axis * self.stem_height))
            return self._action(v, w, True)
        # Lift straight up, the speed ramped up over ``lift_ramp_steps`` (no jerk on the seal).
        self.lift_count += 1
        speed = self.lift_speed * min(1.0, self.lift_count / self.lift_ramp_steps)
        return self._action(np.array([0.0, 0.0, speed]), np.zeros(3), True)


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
    }
