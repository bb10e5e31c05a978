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
