"""The UR5e (``sms3d_env.ur5e``): registered by its own module, its model is Universal Robots'
published DH table, its home pose lies inside its limits with the cup pointing down above the
bed, and the scripted picker picks with it."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import sms3d_env
from sms3d_env.pickers.episode import run_episode
from sms3d_env.pickers.scripted import ScriptedPicker
from sms3d_env.robot import ROBOT_CONAFFINITY, TOOL_CONTYPE, TOOL_SITE, arm_only_model
from sms3d_env.robots import make_robot, registered_robots
from sms3d_env.ur5e import UR5E_JOINTS, UR5eConfig

# Universal Robots' UR5e DH table (m, rad).
DH_D = (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)
DH_A = (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)
DH_ALPHA = (np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0)


def dh_flange(q: np.ndarray) -> np.ndarray:
    """The flange's pose (4 x 4) in the base frame by the DH table."""
    pose = np.eye(4)
    for th, d, a, al in zip(q, DH_D, DH_A, DH_ALPHA):
        ct, st, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
        pose = pose @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                                [0, sa, ca, d], [0, 0, 0, 1]])
    return pose


def test_the_ur5e_is_registered_by_its_own_module_and_builds():
    assert "ur5e" in registered_robots() and "ur5e" in sms3d_env.ROBOTS
    cfg = make_robot("ur5e")
    assert type(cfg) is UR5eConfig and cfg == sms3d_env.UR5eConfig()
    model = arm_only_model(cfg)
    assert [model.joint(i).name for i in range(model.njnt)] == [f"ur5e/{j}" for j in UR5E_JOINTS]
    assert model.nu == 6 and [model.actuator(i).name for i in range(6)] == [f"ur5e/act_{j}" for j in UR5E_JOINTS]
    # Every geom (links and tool) collides with the soil and the mushrooms, not with another link.
    assert set(model.geom_contype) == {TOOL_CONTYPE} and set(model.geom_conaffinity) == {ROBOT_CONAFFINITY}


def test_the_model_follows_the_published_dh_table():
    model = arm_only_model(UR5eConfig(mount_pos=(0.0, 0.0, 0.0)))
    data = mujoco.MjData(model)
    flange = model.body("ur5e/flange").id
    for q in np.random.default_rng(0).uniform(-3.0, 3.0, (5, 6)):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        pose = dh_flange(q)
        np.testing.assert_allclose(data.xpos[flange], pose[:3, 3], atol=1e-9)
        np.testing.assert_allclose(data.xmat[flange].reshape(3, 3), pose[:3, :3], atol=1e-9)
    # The published masses of the six moving links (kg): 17.7 kg.
    moving = sum(model.body_mass[model.body(f"ur5e/{b}").id] for b in (
        "shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link"))
    assert moving == pytest.approx(3.761 + 8.058 + 2.846 + 1.37 + 1.3 + 0.365)


def test_home_is_inside_the_limits_with_the_cup_pointing_down_above_the_bed():
    cfg = UR5eConfig()
    model = arm_only_model(cfg)
    data = mujoco.MjData(model)
    home = np.asarray(cfg.home_q)
    lo, hi = model.jnt_range[:6].T
    assert np.all((lo < home) & (home < hi))
    data.qpos[:] = home
    mujoco.mj_kinematics(model, data)
    site = model.site(f"ur5e/{TOOL_SITE}").id
    np.testing.assert_allclose(data.site_xpos[site], [0.0, 0.0, 0.20], atol=1e-3)  # 20 cm above the patch centre
    assert data.site_xmat[site].reshape(3, 3)[:, 2] @ [0.0, 0.0, -1.0] > np.cos(np.radians(0.5))  # +z: approach
    # Elbow up, every link above the soil.
    assert min(data.xpos[model.body(f"ur5e/{b}").id][2] for b in ("forearm_link", "wrist_1_link")) > 0.3


def test_the_scripted_picker_picks_with_the_ur5e():
    env = gym.make("SMS3DPick-v2", robot="ur5e", scene={"placement": {"num_mushrooms": 8}})
    picker = ScriptedPicker.for_env(env)
    result = run_episode(env, picker, seed=1_000_000)
    assert result["success"], result
    assert env.unwrapped.observation_space["joint_pos"].shape == (6,)
    env.close()
