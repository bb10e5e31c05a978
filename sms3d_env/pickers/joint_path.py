"""The scripted pickers' joint-space transfer (``RobotConfig.approach="joint"``): a straight
joint-space path from the arm's joints to the stand-off configuration, followed by tool twists.

The picker's Cartesian approach moves the tool straight towards the stand-off point while it
turns the cup onto the estimated axis; the arm's joints go wherever that straight line takes
them. For the v1 Jaco (hanging, right-angle adapter) that line folded the arm under its shoulder
for targets 10-22 cm from the mount column and straightened its wrist for tilted axes, and the
differential IK stalled short of the stand-off point (``not_reached``; scripted picker, 400
held-out 25-mushroom beds per error: 10 / 10 / 8 / 20 at 0 / 10 / 20 / 30 deg). A straight path in
joint space between two well-conditioned configurations passes no such point, and a twist that
follows it is one the IK can track: on the same beds none stalled, and 400 / 396 / 390 / 375 were
picked instead of 383 / 377 / 369 / 334 (``benchmarks/bench_robots.py --robots jaco``). A real
arm's planner moves the same way: joint-space motion to a pre-grasp pose, Cartesian from there.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from sms3d_env.posture import POSTURE_OFFSETS
from sms3d_env.robot import TOOL_SITE, RobotSpec, arm_only_model
from sms3d_env.targets import Reachability


def rotation_vector(rot: np.ndarray) -> np.ndarray:
    """The rotation vector (axis times angle, rad) of the 3 x 3 rotation matrix ``rot``."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rot, np.float64).ravel())
    vec = np.empty(3)
    mujoco.mju_quat2Vel(vec, quat, 1.0)
    return vec


class JointSpaceTransfer:
    """Plans, at an episode's first approach step, the straight joint-space path from the arm's
    joints to the configuration with the tool ``offset`` above the estimated cap top on the
    estimated axis, facing down it. The configuration is the one the env's IK posture target
    holds for the same estimate (the same :class:`~sms3d_env.targets.Reachability` solve from
    the same home), so the controller's null-space pull agrees with where the path ends. The
    path is timed by a trapezoidal speed profile that keeps the tool's and every joint's speed
    within ``speed_fraction`` of the controller's limits; each step gives the tool twist that
    follows it.

    Args:
        robot: the arm's configuration (its arm-only model is built here).
        control_dt: the control period (s).
        max_linear_speed, max_angular_speed: the tool's speed limits (m/s, rad/s: the env's
            action scales).
        max_joint_speed: the joints' speed limit (rad/s).
        speed_fraction: the share of each limit the path's fastest point reaches. ASSUMPTION:
            0.9, a margin for the pull back onto the path.
        ramp_time: how long the path accelerates and decelerates (s). ASSUMPTION: 0.2 s.
        gain: the pull of the measured tool back onto the path (1/s). ASSUMPTION: 4, the
            Cartesian approach's proportional gain.
    """

    def __init__(self, robot: RobotSpec, control_dt: float, max_linear_speed: float, max_angular_speed: float,
                 max_joint_speed: float, speed_fraction: float = 0.9, ramp_time: float = 0.2,
                 gain: float = 4.0) -> None:
        self.model = arm_only_model(robot)
        self.data = mujoco.MjData(self.model)
        self.site = self.model.site(robot.prefix + TOOL_SITE).id
        self.qadr = self.model.jnt_qposadr[[self.model.joint(robot.prefix + j).id for j in robot.joints]]
        self.reach = Reachability(self.model, robot.prefix + TOOL_SITE, self.qadr, np.asarray(robot.home_q, float))
        self.dt, self.gain, self.ramp_time = control_dt, gain, ramp_time
        self.limits = speed_fraction * np.array([max_linear_speed, max_angular_speed, max_joint_speed])
        self.poses: list[tuple[np.ndarray, np.ndarray]] = []  # (tool site position, rotation) per step
        self.step = 0

    @classmethod
    def for_env(cls, env: Any, **kwargs: Any) -> JointSpaceTransfer:
        """The transfer for ``env``'s arm at its controller's limits."""
        u = env.unwrapped
        c = u.ctrl_cfg
        return cls(u.robot_cfg, c.control_dt, c.max_linear_speed, c.max_angular_speed, c.max_joint_speed,
                   **kwargs)

    def tool_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tool site's position (m, world) and rotation (3 x 3) at arm joints ``q``."""
        self.data.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        return self.data.site_xpos[self.site].copy(), self.data.site_xmat[self.site].reshape(3, 3).copy()

    def plan(self, q_start: np.ndarray, cap_top: np.ndarray, axis: np.ndarray, offset: float) -> bool:
        """Plan the path from joints ``q_start`` to the stand-off configuration for the estimated
        ``cap_top`` (m) and unit ``axis``; False (no path) where that pose has no IK solution."""
        # Solved from home through the IK posture target's first pose, as that target is.
        q_end = self.reach.solve(cap_top, axis, (POSTURE_OFFSETS[0], offset))
        self.poses, self.step = [], 0
        if q_end is None:
            return False
        q_start = np.asarray(q_start, float)
        grid = [self.tool_pose(q_start + s * (q_end - q_start)) for s in np.linspace(0.0, 1.0, 41)]
        # The fastest rates along the path per unit of path parameter: tool (m, rad) and joints (rad).
        rates = np.array([
            max(np.linalg.norm(b[0] - a[0]) for a, b in zip(grid, grid[1:])),
            max(np.linalg.norm(rotation_vector(b[1] @ a[1].T)) for a, b in zip(grid, grid[1:])),
            0.0,
        ]) * (len(grid) - 1)
        rates[2] = np.abs(q_end - q_start).max()
        cruise = 1.0 / max((rates / self.limits).max(), 1e-9)  # path parameter per second
        ramp = min(self.ramp_time, 1.0 / cruise)
        steps = max(1, int(np.ceil((1.0 / cruise + ramp) / self.dt)))
        duration = steps * self.dt
        cruise = 1.0 / (duration - ramp)
        self.poses = [self.tool_pose(q_start + s * (q_end - q_start))
                      for s in self._profile(np.arange(steps + 1) * self.dt, duration, ramp, cruise)]
        return True

    @staticmethod
    def _profile(t: np.ndarray, duration: float, ramp: float, cruise: float) -> np.ndarray:
        """The path parameter in [0, 1] at times ``t`` (s): constant acceleration for ``ramp``
        seconds, ``cruise`` per second, constant deceleration for the last ``ramp`` seconds."""
        s = np.where(t < ramp, cruise * t ** 2 / (2 * ramp), cruise * (t - ramp / 2))
        end = duration - t
        s = np.where(end < ramp, 1.0 - cruise * end ** 2 / (2 * ramp), s)
        return np.clip(s, 0.0, 1.0)

    @property
    def done(self) -> bool:
        """Whether the planned path has been followed to its end (or none was planned)."""
        return self.step >= len(self.poses) - 1

    def twist(self, position: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The next step's tool twist (m/s, rad/s, world) for the measured tool ``position`` (m)
        and ``rotation`` (3 x 3): the path's own motion over the step, plus ``gain`` times the
        tool's deviation from where the path is now."""
        (p_now, r_now), (p_next, r_next) = self.poses[self.step], self.poses[self.step + 1]
        self.step += 1
        linear = (p_next - p_now) / self.dt + self.gain * (p_now - position)
        angular = rotation_vector(r_next @ r_now.T) / self.dt + self.gain * rotation_vector(r_now @ rotation.T)
        return linear, angular
