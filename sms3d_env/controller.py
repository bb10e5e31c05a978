"""Differential-IK tool controller: a normalised tool twist in, joint position targets out.

Each control step, mink solves one QP (FrameTask on the tool site, PostureTask, joint position and
velocity limits, solver daqp) on an arm-only model, so its cost does not grow with the number of
mushrooms. The IK state is the *commanded* configuration; the actuators track it. The frame
task's target is an anchored goal pose that integrates the commanded twists, so what the QP
concedes in one step (to the posture task, to the joint-speed box) is made up in the next instead
of accumulating as drift. When contact stops the arm, the command may lead the measured joints by
at most ``max_lead`` rad, which bounds how hard the tool can press, and the goal is held within
``GOAL_LEAD_STEPS_POS`` / ``GOAL_LEAD_STEPS_ANGLE`` steps of motion of the commanded tool pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mink
import mujoco
import numpy as np

from sms3d_env.records import check_choice, check_int, check_number
from sms3d_env.robot import TOOL_SITE, RobotSpec, arm_only_model

#: The IK's null-space posture rules (``ControllerConfig.posture_target``; :mod:`sms3d_env.posture`).
POSTURE_TARGETS = ("estimate", "tool")

#: How far the goal pose may lead the commanded tool pose, in control steps at the top speeds
#: (``max_linear_speed`` / ``max_angular_speed`` x ``control_dt``; by default 9.6 mm, 0.032 rad).
#: The position lead is above what the QP concedes in a step (~0.1 mm on the Jaco's free twist,
#: more as an arm nears a joint's limit), so the concession is made up rather than forgotten, yet
#: small: while contact holds the arm the goal cannot run on with the twist, and a tool that stalled
#: against something is not snapped far once it comes free. The angle lead is one step, just
#: enough for a free rotation at full speed: when the root holds the wrist back (the command
#: clamped at ``max_lead``), the QP chases the rest of the turn with the shoulder and elbow, which
#: swings the tool sideways; on the v1 Jaco's twist (10 scripted picks) that drift was at most
#: 8 mm with one step, 14 mm with 1.25 and ~120 mm with two.
GOAL_LEAD_STEPS_POS = 2.0
GOAL_LEAD_STEPS_ANGLE = 1.0


@dataclass(frozen=True)
class ControllerConfig:
    """Control period, speeds and IK weights (the env's ``controller`` argument, or its mapping
    form, e.g. ``{"posture_target": "tool"}``).

    Attributes:
        control_dt: the control period (s): one action per period.
        substeps: physics steps per control period (the physics step is ``control_dt /
            substeps``): 10 x 4 ms. With the seal read over its response time, 400 scripted
            picks per robot and error (0-30 deg) end the same at 1, 2 and 4 ms to within one
            episode (the removed v0 stepped 20 x 2 ms).
        posture_target: the IK's null-space posture (:mod:`sms3d_env.posture`): ``"estimate"``
            (default) a pre-grasp configuration solved once per episode for the *estimated*
            axis; ``"tool"`` solved again whenever the tool axis turns more than 5 deg away from
            the axis of the last solve, so a picker that corrects a wrong estimate is not pulled
            back towards it.
        max_linear_speed: tool speed at |action| = 1 (m/s). ASSUMPTION: a safe speed near produce.
        max_angular_speed: tool angular speed at |action| = 1 (rad/s). ASSUMPTION.
        max_joint_speed: per-joint velocity limit of revolute joints in the IK (rad/s); Jaco's
            rating is ~0.8-1.0.
        max_slide_speed: the same for prismatic joints (the gantry's rails and lift, m/s).
            ASSUMPTION: 0.5 m/s, moderate for belt-driven gantries.
        max_lead: largest gap between commanded and measured joint angle (rad).
        max_slide_lead: the same for prismatic joints (m). ASSUMPTION: 3 mm. (Either command
            may lead by this plus one step's motion; what bounds the gantry's pressing force is
            its lift's force limit, ``GantryConfig.lift_force``.)
        position_cost, orientation_cost, posture_cost: mink task weights.
        damping: Levenberg-Marquardt damping of the IK QP.
    """

    control_dt: float = 0.04
    substeps: int = 10
    posture_target: str = "estimate"
    max_linear_speed: float = 0.12
    max_angular_speed: float = 0.8
    max_joint_speed: float = 1.0
    max_slide_speed: float = 0.5
    max_lead: float = 0.03
    max_slide_lead: float = 0.003
    position_cost: float = 1.0
    orientation_cost: float = 0.3
    posture_cost: float = 1e-2
    damping: float = 1e-4

    def __post_init__(self) -> None:
        for name in ("control_dt", "max_linear_speed", "max_angular_speed", "max_joint_speed", "max_slide_speed",
                     "max_lead", "max_slide_lead"):
            check_number(f"ControllerConfig.{name}", getattr(self, name), 1e-9, math.inf, "a finite number > 0")
        check_int("ControllerConfig.substeps", self.substeps, 1)
        check_choice("ControllerConfig.posture_target", self.posture_target, POSTURE_TARGETS)


class ArmBoxLimit(mink.Limit):
    """The arm's joint position limits and speed limit as one box on the IK step ``dq``.

    The same feasible set as mink's ``ConfigurationLimit`` (same ``gain``) together with a
    ``VelocityLimit``, built on one constant ``G = [I; -I]`` over the arm's dofs: the pair
    rebuilt and stacked their matrices every step, a third of the controller's time.
    """

    def __init__(self, model: mujoco.MjModel, joints: list[str], max_speed: np.ndarray,
                 gain: float = 0.95) -> None:
        ids = [model.joint(j).id for j in joints]
        self.qadr = model.jnt_qposadr[ids]
        rows = np.eye(model.nv)[model.jnt_dofadr[ids]]
        self.G = np.vstack([rows, -rows])
        limited = model.jnt_limited[ids].astype(bool)
        self.lower = np.where(limited, model.jnt_range[ids, 0], -np.inf)
        self.upper = np.where(limited, model.jnt_range[ids, 1], np.inf)
        self.max_speed, self.gain = np.asarray(max_speed, float), gain

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        q = configuration.data.qpos[self.qadr]
        step = self.max_speed * dt
        h = np.concatenate([np.minimum(step, self.gain * (self.upper - q)),
                            np.minimum(step, self.gain * (q - self.lower))])
        return mink.Constraint(G=self.G, h=h)


class IKController:
    """Turns world-frame tool twists into commanded arm joint angles with mink."""

    def __init__(self, robot: RobotSpec, cfg: ControllerConfig) -> None:
        self.cfg, self.dt = cfg, cfg.control_dt
        self.model = arm_only_model(robot)
        self.configuration = mink.Configuration(self.model)
        self.site = robot.prefix + TOOL_SITE
        self.site_id = self.model.site(self.site).id
        joints = [robot.prefix + j for j in robot.joints]
        ids = [self.model.joint(j).id for j in joints]
        self.arm_qadr = self.model.jnt_qposadr[ids]
        slide = self.model.jnt_type[ids] == mujoco.mjtJoint.mjJNT_SLIDE
        self.max_lead = np.where(slide, cfg.max_slide_lead, cfg.max_lead)
        self.frame_task = mink.FrameTask(self.site, "site", position_cost=cfg.position_cost,
                                         orientation_cost=cfg.orientation_cost, lm_damping=1e-3)
        # No posture cost on the last joint (the tool roll): the picker leaves the roll free.
        cost = np.full(self.model.nv, cfg.posture_cost)
        cost[self.model.jnt_dofadr[ids[-1]]] = 0.0
        self.posture_task = mink.PostureTask(self.model, cost=cost)
        self.tasks = [self.frame_task, self.posture_task]
        speeds = np.where(slide, cfg.max_slide_speed, cfg.max_joint_speed)
        self.limits = [ArmBoxLimit(self.model, joints, speeds)]
        self.goal = mink.SE3.identity()  # the frame task's anchored target; reset() sets it
        self.goal_max_lead = (GOAL_LEAD_STEPS_POS * cfg.max_linear_speed * self.dt,
                              GOAL_LEAD_STEPS_ANGLE * cfg.max_angular_speed * self.dt)

    def reset(self, q_arm: np.ndarray, q_home: np.ndarray | None = None) -> None:
        """Set the commanded configuration (and the posture target) to ``q_arm``, and the goal
        pose to the tool pose there."""
        q = self.model.qpos0.copy()
        q[self.arm_qadr] = q_arm
        self.configuration.update(q)
        pos, quat = self._commanded_pose()
        self.goal = mink.SE3(np.concatenate([quat, pos]))
        home = q.copy()
        if q_home is not None:
            home[self.arm_qadr] = q_home
        self.posture_task.set_target(home)

    def set_posture(self, q_arm: np.ndarray) -> None:
        """Move the posture target (the null-space pull) to ``q_arm``; the command stays. Call
        after ``reset``, which sets the first target."""
        home = self.posture_task.target_q.copy()
        home[self.arm_qadr] = q_arm
        self.posture_task.set_target(home)

    def _solve(self, target: mink.SE3, dt: float) -> np.ndarray:
        self.frame_task.set_target(target)
        v = mink.solve_ik(self.configuration, self.tasks, dt, "daqp", damping=self.cfg.damping,
                          limits=self.limits)
        self.configuration.integrate_inplace(v, dt)
        return self.configuration.q[self.arm_qadr]

    def _commanded_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The tool site's position and quaternion (w, x, y, z) at the commanded configuration."""
        d = self.configuration.data
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, d.site_xmat[self.site_id])
        return d.site_xpos[self.site_id].copy(), quat

    def _held_near_command(self, pos: np.ndarray, quat: np.ndarray) -> mink.SE3:
        """The pose ``(pos, quat)`` moved back to within ``goal_max_lead`` (m, rad) of the
        commanded tool pose, along the straight line and the shortest turn towards it."""
        max_dist, max_angle = self.goal_max_lead
        cmd_pos, cmd_quat = self._commanded_pose()
        ahead = pos - cmd_pos
        dist = np.linalg.norm(ahead)
        if dist > max_dist:
            pos = cmd_pos + ahead * (max_dist / dist)
        inv, turn, rotvec = np.empty(4), np.empty(4), np.empty(3)
        mujoco.mju_negQuat(inv, cmd_quat)
        mujoco.mju_mulQuat(turn, quat, inv)
        mujoco.mju_quat2Vel(rotvec, turn, 1.0)  # the world-frame turn from command to goal
        angle = np.linalg.norm(rotvec)
        if angle > max_angle:
            mujoco.mju_axisAngle2Quat(turn, rotvec / angle, max_angle)
            mujoco.mju_mulQuat(quat, turn, cmd_quat)
        return mink.SE3(np.concatenate([quat, pos]))

    def step(self, twist: np.ndarray, q_measured: np.ndarray) -> np.ndarray:
        """Apply a world-frame twist (m/s, rad/s about the tool site) for one control period;
        ``mink.exceptions.NoSolutionFound`` when the QP has no solution (the goal then stays)."""
        q = self.configuration.q
        gap = q[self.arm_qadr] - q_measured
        if (np.abs(gap) > self.max_lead + 1e-8).any():
            q[self.arm_qadr] = q_measured + gap.clip(-self.max_lead, self.max_lead)
            self.configuration.update(q)
        # Target = the goal (not the commanded pose) moved by the twist, the rotation composed in
        # quaternions (no rotation-matrix round trip).
        quat, pos = self.goal.wxyz_xyz[:4].copy(), self.goal.wxyz_xyz[4:] + twist[:3] * self.dt
        w = twist[3:] * self.dt
        angle = math.hypot(*w)
        if angle > 0.0:
            turn = np.empty(4)
            mujoco.mju_axisAngle2Quat(turn, w / angle, angle)
            mujoco.mju_mulQuat(quat, turn, quat.copy())
            mujoco.mju_normalize4(quat)  # the goal composes turns over a whole episode
        goal = self._held_near_command(pos, quat)
        q_arm = self._solve(goal, self.dt)
        self.goal = goal
        return q_arm
