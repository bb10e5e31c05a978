"""The differential-IK controller (``sms3d_env.controller``) on the arm-only model: one step
follows the commanded tool twist, the commands stay within the joint limits and speeds, and the
command leads the measured joints by at most ``max_lead``."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sms3d_env.controller import ControllerConfig, IKController
from sms3d_env.gantry import GantryConfig
from sms3d_env.robot import RobotSpec
from sms3d_env.robots import HANGING_JACO

ROBOTS = {"jaco": HANGING_JACO, "gantry": GantryConfig()}
CONFIG = ControllerConfig()


@pytest.fixture(scope="module", params=list(ROBOTS))
def robot(request) -> RobotSpec:
    return ROBOTS[request.param]


@pytest.fixture(scope="module")
def ik(robot) -> IKController:
    return IKController(robot, CONFIG)


def _tool_pose(ik: IKController, q_arm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tool site's position (m) and rotation matrix on the arm-only model at ``q_arm``."""
    m = ik.model
    d = mujoco.MjData(m)
    d.qpos[ik.arm_qadr] = q_arm
    mujoco.mj_kinematics(m, d)
    return d.site_xpos[ik.site_id].copy(), d.site_xmat[ik.site_id].reshape(3, 3).copy()


def _joint_box(ik: IKController) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower and upper limits (inf where unlimited) and the speed limit of each arm joint."""
    box = ik.limits[0]
    return box.lower, box.upper, box.max_speed


@pytest.mark.parametrize("twist", [
    [0.1, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.0, 0.1, 0.0, 0.0, 0.0, 0.0],
    [0.0, 0.0, -0.1, 0.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 0.5, 0.0, 0.0],
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.5],
], ids=["x", "y", "down", "roll", "yaw"])
def test_one_step_moves_the_tool_by_the_commanded_twist(robot, ik, twist):
    """Linear (m/s) and angular (rad/s, about the tool site) velocity over one control period,
    each within 5 % of the commanded speed, from home."""
    twist = np.asarray(twist)
    home = np.asarray(robot.home_q)
    ik.reset(home)
    q = ik.step(twist, home)
    p0, r0 = _tool_pose(ik, home)
    p1, r1 = _tool_pose(ik, q)
    turn, rotvec = np.empty(4), np.empty(3)
    mujoco.mju_mat2Quat(turn, (r1 @ r0.T).ravel())
    mujoco.mju_quat2Vel(rotvec, turn, CONFIG.control_dt)
    moved = np.r_[(p1 - p0) / CONFIG.control_dt, rotvec]
    assert np.linalg.norm(moved - twist) <= 0.05 * np.linalg.norm(twist), moved


@pytest.mark.parametrize("twist", [[0.12, 0.0, 0.12, 0.0, 0.0, 0.0], [0.0, -0.12, -0.12, 0.0, 0.8, 0.0]],
                         ids=["out-up", "aside-down-tilting"])
def test_commands_stay_within_the_joint_limits_and_speeds(robot, ik, twist):
    """Driven by one twist for 12 s (beyond the workspace): every command within the limits,
    every step's change within the speed limit x the control period; a limit is reached."""
    lower, upper, speed = _joint_box(ik)
    q = np.asarray(robot.home_q, float)
    ik.reset(q)
    for _ in range(300):
        command = ik.step(np.asarray(twist), q)
        assert ((lower - 1e-9 <= command) & (command <= upper + 1e-9)).all(), command
        assert (np.abs(command - q) <= speed * CONFIG.control_dt + 1e-9).all()
        q = command
    span = np.where(np.isfinite(upper - lower), upper - lower, np.inf)
    at_limit = np.minimum(q - lower, upper - q) <= 0.01 * span
    assert at_limit.any(), q


def test_the_command_leads_the_measured_joints_by_at_most_max_lead(robot, ik):
    """Contact holds the arm back: whatever the IK commanded before, the next command starts from
    the measured joints plus at most ``max_lead`` (then moves one step)."""
    _, _, speed = _joint_box(ik)
    home = np.asarray(robot.home_q, float)
    ik.reset(home)
    held_back = home - 0.05  # 0.05 rad (m on a slide) behind the command on every joint, within the limits
    command = ik.step(np.zeros(6), held_back)
    assert (np.abs(command - held_back) <= ik.max_lead + speed * CONFIG.control_dt + 1e-9).all()
    assert (np.abs(command - held_back) < np.abs(home - held_back)).all()


def test_a_long_free_twist_keeps_the_tool_in_place(robot, ik):
    """The scripted picker's twist with no contact (45 steps at 0.8 rad/s about a tilted axis
    through the tool site, the joints tracking the command): the tool stays within 1 mm of where
    it started and turns through the integrated angle about that axis. The IK's target is the
    anchored goal, not the last command moved by the twist: from the command, what the QP
    conceded to the posture task each step added up to 5-6 mm on the Jaco."""
    home = np.asarray(robot.home_q, float)
    p0, r0 = _tool_pose(ik, home)
    axis = r0[:, 2] + 0.5 * r0[:, 0]
    axis /= np.linalg.norm(axis)
    ik.reset(home)
    q, steps = home, 45
    for _ in range(steps):
        q = ik.step(np.r_[0.0, 0.0, 0.0, 0.8 * axis], q)
    p1, r1 = _tool_pose(ik, q)
    turn, rotvec = np.empty(4), np.empty(3)
    mujoco.mju_mat2Quat(turn, (r1 @ r0.T).ravel())
    mujoco.mju_quat2Vel(rotvec, turn, 1.0)
    assert np.linalg.norm(p1 - p0) < 1e-3, p1 - p0
    assert np.linalg.norm(rotvec - 0.8 * CONFIG.control_dt * steps * axis) < 0.05, rotvec


def test_the_goal_stays_near_the_command_while_the_arm_is_held(robot, ik):
    """Contact holds the arm at home while the twist commands a move and a turn for 2 s: the goal
    does not run on with the twist, it stays within its lead of the commanded tool pose."""
    home = np.asarray(robot.home_q, float)
    ik.reset(home)
    for _ in range(50):
        ik.step(np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.5]), home)
    pos, rot = _tool_pose(ik, ik.configuration.q[ik.arm_qadr])
    goal = np.empty(9)
    mujoco.mju_quat2Mat(goal, ik.goal.wxyz_xyz[:4])
    turn, rotvec = np.empty(4), np.empty(3)
    mujoco.mju_mat2Quat(turn, (goal.reshape(3, 3) @ rot.T).ravel())
    mujoco.mju_quat2Vel(rotvec, turn, 1.0)
    max_dist, max_angle = ik.goal_max_lead
    assert np.linalg.norm(ik.goal.wxyz_xyz[4:] - pos) <= max_dist + 1e-9
    assert np.linalg.norm(rotvec) <= max_angle + 1e-9
