"""Scripted pose-aware picker: the baseline policy, driven only by the observation.

Phases: approach a stand-off point above the *estimated* cap top along the estimated stem axis
with the cup facing down the axis; descend along the axis with suction on until the cup seals;
twist about the estimated stem axis ("twist, do not pull", optionally with a gentle bend) until
the vacuum sensor's seal load falls (the root let go); lift straight up. A wrong estimate tilts the cup against the cap (no seal, or a contact off the cap
top) and twists about the wrong axis, which bends the root and the seal. ``HandPicker`` does the
same with the Jaco hand: open, descend around the cap, close, twist, lift. For an arm whose
straight Cartesian approach crosses a singularity (``RobotConfig.approach="joint"``: the v1 Jaco),
the approach first follows a straight joint-space path to the stand-off configuration
(:mod:`sms3d_env.pickers.joint_path`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import gymnasium as gym
import mujoco
import numpy as np

from sms3d_env.pickers.joint_path import JointSpaceTransfer


def _tool_rotation(quat: np.ndarray) -> np.ndarray:
    """The tool frame's rotation (3 x 3, world) from the observed quaternion (w, x, y, z)."""
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, np.float64))
    return mat.reshape(3, 3)


class _View(NamedTuple):
    """What every phase reads from the observation."""

    p: np.ndarray  # tool site position
    rot: np.ndarray  # tool frame rotation (3 x 3, world)
    z: np.ndarray  # tool axis (approach direction: the frame's z)
    q: np.ndarray  # arm joints (rad or m)
    c: np.ndarray  # estimated cap top
    axis: np.ndarray  # estimated stem axis (unit)
    held: bool  # the tool holds a mushroom (sealed, or pinched by the fingers)
    load: float  # suction: the seal's load / capacity; hand: the finger force (N)


class ScriptedPicker:
    """Approach, seal, twist (with a gentle bend), lift. Call ``reset()`` at each episode start.

    Phases, all along the *estimated* pose from the observation:

    1. ``approach``: move to a stand-off point above the estimated cap top on the estimated stem
       axis, the cup facing down that axis (with a ``transfer``: first along a straight
       joint-space path to the arm configuration there, planned at the phase's first step);
    2. ``descend``: move down the axis with suction on until the cup seals (or give up);
    3. ``twist``: rotate about the estimated stem axis through the cup ("twist, do not pull"),
       with a slight pull along the axis and an optional gentle bend about the estimated stem
       base, until detachment is sensed (the seal's load, ``obs["suction"][2]``, falls below
       ``detach_drop`` of its peak in the twist) or for ``twist_steps`` at most; a wrong axis
       turns part of the twist into bending of the root and the seal;
    4. ``lift``: straight up, the speed ramped up (no jerk on the seal).

    ``for_env`` returns a ``HandPicker`` for an env with the hand.

    Args:
        max_linear_speed, max_angular_speed: the env's action scales (m/s, rad/s).
        standoff: approach point above the estimated cap top along the axis (m).
        stem_height: assumed cap-top-to-stem-base distance for the bend pivot (m).
        descend_speed: approach speed along the axis once at the stand-off point (m/s).
        twist_rate: rad/s about the estimated axis, for at most ``twist_steps`` control steps.
        detach_drop: the twist ends once the seal's load has fallen below this fraction of its
            peak in the twist (a peak of at least ``detach_min_load``): the root let go and the
            load it carried is gone. None: twist ``twist_steps`` always.
        bend_rate: rad/s of gentle bend (about a horizontal axis, pivot at the estimated stem base).
        pull_speed: withdrawal along the axis while twisting (m/s). 0: pulling at 2 mm/s (the
            v1 picker) loads the seal on top of the twist and overloaded it in 7 of 40 picks at a
            10° axis error on SMS3DPick-v2, against 1 of 40 without.
        lift_speed, lift_ramp_steps: lift speed (m/s), reached linearly over this many steps.
        settle_steps: still steps after the seal forms (the arm stops pressing).
        transfer: the joint-space path of the approach (:class:`JointSpaceTransfer`), or None
            (a Cartesian approach only). ``for_env`` gives one to robots with
            ``approach="joint"``.
    """

    approach_command = -1.0  # tool command on the way in (suction off)
    hold_command = 1.0  # tool command from the grip on (suction on)

    def __init__(self, max_linear_speed: float = 0.12, max_angular_speed: float = 0.8,
                 control_dt: float = 0.04, standoff: float = 0.03, stem_height: float = 0.04,
                 descend_speed: float = 0.02, twist_rate: float = 0.8, bend_rate: float = 0.0,
                 twist_steps: int = 45, pull_speed: float = 0.0, settle_steps: int = 2,
                 lift_speed: float = 0.06, lift_ramp_steps: int = 5,
                 transfer: JointSpaceTransfer | None = None, detach_drop: float | None = 0.5,
                 detach_min_load: float = 0.1) -> None:
        self.vmax, self.wmax, self.dt = max_linear_speed, max_angular_speed, control_dt
        self.standoff, self.stem_height = standoff, stem_height
        self.descend_speed, self.bend_rate, self.twist_rate = descend_speed, bend_rate, twist_rate
        self.twist_steps, self.pull_speed, self.settle_steps = twist_steps, pull_speed, settle_steps
        self.lift_speed, self.lift_ramp_steps = lift_speed, lift_ramp_steps
        self.transfer = transfer
        self.detach_drop, self.detach_min_load = detach_drop, detach_min_load
        self.reset()

    @classmethod
    def for_env(cls, env: gym.Env, **kwargs: Any) -> ScriptedPicker:
        """The picker for ``env``'s tool, at ``env``'s action scales, with a joint-space transfer
        where ``env``'s robot asks for one (``approach="joint"``)."""
        u = env.unwrapped
        picker = HandPicker if u.tool == "hand" else ScriptedPicker
        if u.robot_cfg.approach == "joint":
            kwargs.setdefault("transfer", JointSpaceTransfer.for_env(env))
        return picker(u.ctrl_cfg.max_linear_speed, u.ctrl_cfg.max_angular_speed, u.control_dt, **kwargs)

    def reset(self) -> None:
        self.phase = "approach"
        self.planned = False  # whether this episode's approach has planned its transfer
        self.count = 0
        self.descended = 0.0
        self.lift_count = 0
        self.peak_load = 0.0  # the seal's largest load in this twist

    def _action(self, v: np.ndarray, w: np.ndarray, command: float) -> np.ndarray:
        a = np.concatenate([v / self.vmax, w / self.wmax, [command]])
        return np.clip(a, -1, 1).astype(np.float32)

    def approach_goal(self, o: _View) -> np.ndarray:
        """Where the approach ends (the tool site): the stand-off point above the cap top."""
        return o.c + o.axis * self.standoff

    @staticmethod
    def view(obs: dict[str, np.ndarray]) -> _View:
        """What the phases read from ``obs`` (the pose is ``obs["target_pose"]``)."""
        axis = obs["target_pose"][3:]
        rot = _tool_rotation(obs["tool_pose"][3:])
        return _View(p=obs["tool_pose"][:3], rot=rot, z=rot[:, 2], q=obs["joint_pos"],
                     c=obs["target_pose"][:3], axis=axis / np.linalg.norm(axis),
                     held=bool(obs["suction"][1] > 0.5), load=float(obs["suction"][2]))

    def __call__(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return getattr(self, "_" + self.phase)(self.view(obs))

    def _align(self, o: _View) -> np.ndarray:
        """Angular velocity turning the tool axis onto the estimated stem axis (facing down it)."""
        return 3.0 * np.cross(o.z, -o.axis)

    def _approach(self, o: _View) -> np.ndarray:
        if self.transfer is not None:
            if not self.planned:
                self.planned = True
                self.transfer.plan(o.q, o.c, o.axis, float((self.approach_goal(o) - o.c) @ o.axis))
            if not self.transfer.done:
                return self._action(*self.transfer.twist(o.p, o.rot), self.approach_command)
        err = self.approach_goal(o) - o.p
        ang = np.degrees(np.arccos(np.clip(o.z @ -o.axis, -1, 1)))
        if np.linalg.norm(err) < 0.003 and ang < 3.0:
            self.phase = "descend"
        # Proportional, at least 2 cm/s until the tolerance (no slow creep near the goal).
        n_err = np.linalg.norm(err)
        speed = min(self.vmax, max(4.0 * n_err, 0.02))
        v = err / max(n_err, 1e-9) * speed
        return self._action(v, self._align(o), self.approach_command)

    def _descend_velocity(self, o: _View) -> np.ndarray:
        """Down the estimated axis, pulled back onto it."""
        rel = o.p - o.c
        lateral = rel - (rel @ o.axis) * o.axis
        return -o.axis * self.descend_speed - 4.0 * lateral

    def _descend(self, o: _View) -> np.ndarray:
        if o.held:
            self.phase, self.count = "settle", 0
            return self._action(np.zeros(3), np.zeros(3), self.hold_command)
        self.descended += self.descend_speed * self.dt
        if self.descended > self.standoff + 0.02:
            self.phase = "lift"
        return self._action(self._descend_velocity(o), self._align(o), self.hold_command)

    def _settle(self, o: _View) -> np.ndarray:
        self.count += 1
        if self.count >= self.settle_steps:
            self.phase, self.count = "twist", 0
        return self._action(np.zeros(3), np.zeros(3), self.hold_command)

    def _twist(self, o: _View) -> np.ndarray:
        self.count += 1
        self.peak_load = max(self.peak_load, o.load)
        released = (self.detach_drop is not None and self.peak_load >= self.detach_min_load
                    and o.load < self.detach_drop * self.peak_load)
        if released or self.count >= self.twist_steps:
            self.phase = "lift"
            return self._lift(o)
        return self._action(*self._twist_velocity(o), self.hold_command)

    def _twist_velocity(self, o: _View) -> tuple[np.ndarray, np.ndarray]:
        """(linear, angular) velocity of the twist about ``o``'s axis, with the pull and bend."""
        w = self.twist_rate * o.axis
        v = self.pull_speed * o.axis
        if self.bend_rate > 0:
            horiz = np.array([o.axis[0], o.axis[1], 0.0])
            if np.linalg.norm(horiz) < 0.05:
                horiz = np.array([1.0, 0.0, 0.0])
            bend_axis = np.cross(np.array([0.0, 0.0, 1.0]), horiz)
            bend_axis /= np.linalg.norm(bend_axis)
            wb = self.bend_rate * bend_axis
            w = w + wb
            v = v + np.cross(wb, o.p - (o.c - o.axis * self.stem_height))
        return v, w

    def _lift(self, o: _View) -> np.ndarray:
        # Straight up, the speed ramped up over ``lift_ramp_steps`` (no jerk on the grip).
        self.lift_count += 1
        speed = self.lift_speed * min(1.0, self.lift_count / self.lift_ramp_steps)
        return self._action(np.array([0.0, 0.0, speed]), np.zeros(3), self.hold_command)


class HandPicker(ScriptedPicker):
    """The scripted picker for the Jaco 3-finger hand: approach above the estimated cap top along
    the estimated axis with the fingers opened to ``preshape``, descend until the grip site is
    ``grasp_offset`` above the cap top (the closing fingertips then meet the cap's side below
    its top), close for ``close_steps``, twist (and bend), lift with the hand closed.

    Args (besides ``ScriptedPicker``'s):
        grasp_offset: grip site above the estimated cap top at the grasp, along the axis (m).
        preshape: finger command while approaching (-1 open, +1 closed): open wide enough for the
            largest caps, no wider (the fingertips sweep through fewer neighbours).
        close_steps: control steps to close the fingers before twisting.
    """

    def __init__(self, *args: Any, grasp_offset: float = 0.0, preshape: float = -0.4,
                 close_steps: int = 12, **kwargs: Any) -> None:
        self.grasp_offset, self.approach_command = grasp_offset, preshape
        self.close_steps = close_steps
        # The fingers' force does not fall when the root lets go: twist the full twist_steps.
        kwargs.setdefault("detach_drop", None)
        kwargs.setdefault("twist_steps", 30)
        super().__init__(*args, **kwargs)

    def approach_goal(self, o: _View) -> np.ndarray:
        return o.c + o.axis * (self.grasp_offset + self.standoff)

    def _descend(self, o: _View) -> np.ndarray:
        # Close at the grasp point, or where the descent stalls (a finger on the soil or on a
        # neighbour), once the commanded travel exceeds the stand-off by 2 cm.
        self.descended += self.descend_speed * self.dt
        if (o.p - o.c) @ o.axis <= self.grasp_offset or self.descended > self.standoff + 0.02:
            self.phase, self.count = "close", 0
            return self._close(o)
        return self._action(self._descend_velocity(o), self._align(o), self.approach_command)

    def _close(self, o: _View) -> np.ndarray:
        self.count += 1
        if self.count >= self.close_steps:
            self.phase, self.count = "twist", 0
        return self._action(np.zeros(3), self._align(o), self.hold_command)
