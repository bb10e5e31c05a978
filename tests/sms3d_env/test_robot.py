"""The robots (``sms3d_env.robot``, ``gantry``, ``robots``): which links collide with what, the
home pose within the joint limits and where it holds the tool, and the configurations' refusals."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import sms3d_env  # noqa: F401  (registers the ids)
from sms3d_env.gantry import GantryConfig
from sms3d_env.robot import TOOL_SITE, RobotConfig, arm_only_model
from sms3d_env.robots import HANGING_JACO

# The mapping form: v2's placement, no two collision hulls interpenetrating.
SMALL = {"placement": {"num_mushrooms": 8}}

TOOL_GEOMS = {
    "suction": ["jaco/tube", "jaco/flange", "jaco/cup_face"],
    "hand": ["jaco/hand_link_6_main", "jaco/hand_finger_knuckle_1", "jaco/hand_finger_tip_2"],
}


@pytest.mark.parametrize("tool", list(TOOL_GEOMS))
def test_every_jaco_link_and_the_tool_collide_with_soil_and_mushrooms_not_with_each_other(tool, can_touch):
    env = gym.make("SMS3DPick-v2", robot="jaco", scene=SMALL, tool=tool).unwrapped
    env.reset(seed=0)
    m, w = env.model, env.world
    soil = m.geom("terrain").id
    cap = int(env.world.cap_geoms[env.picking.state.target])
    names = ["jaco/ring_5", "jaco/link_5", "jaco/ring_6", *TOOL_GEOMS[tool]]
    geoms = [m.geom(n).id for n in names]
    for g in geoms:
        assert can_touch(m, g, soil) and can_touch(m, g, cap), m.geom(g).name
        body = m.geom_bodyid[g]  # the broadphase prunes by the per-body unions of the masks
        assert m.body_contype[body] & m.geom_contype[g] == m.geom_contype[g]
    for g1 in geoms:
        for g2 in geoms:
            assert not can_touch(m, g1, g2)
    # No link passes through the soil (the removed v0's Jaco had five that did).
    ghosts = {m.body(int(m.geom_bodyid[g])).name for g in np.nonzero(w.robot_geom)[0]
              if not can_touch(m, g, w.terrain_geom)}
    assert ghosts == set()


ROBOT_CONFIGS = {"jaco": HANGING_JACO, "gantry": GantryConfig()}


@pytest.mark.parametrize("tool", ["suction", "hand"])
@pytest.mark.parametrize("name", list(ROBOT_CONFIGS))
def test_home_lies_within_the_joint_limits_and_points_the_tool_down(name, tool):
    """The IK's joint-limit box needs a start inside the limits; the cup starts 20 cm above the
    patch centre, pointing down (the configurations' documented home)."""
    cfg = dataclasses.replace(ROBOT_CONFIGS[name], tool=tool)
    m = arm_only_model(cfg)
    d = mujoco.MjData(m)
    ids = [m.joint(cfg.prefix + j).id for j in cfg.joints]
    home = np.asarray(cfg.home_q)
    limited = m.jnt_limited[ids].astype(bool)
    assert limited.any()
    lower, upper = m.jnt_range[ids].T
    assert ((lower <= home) & (home <= upper))[limited].all(), (home, m.jnt_range[ids])
    d.qpos[m.jnt_qposadr[ids]] = home
    mujoco.mj_kinematics(m, d)
    site = m.site(cfg.prefix + TOOL_SITE).id
    approach = d.site_xmat[site].reshape(3, 3)[:, 2]
    assert np.degrees(np.arccos(np.clip(-approach[2], -1.0, 1.0))) < 1.0
    if tool == "suction":
        np.testing.assert_allclose(d.site_xpos[site], [0.0, 0.0, 0.20], atol=1e-3)


@pytest.mark.parametrize("make, field", [
    (lambda: RobotConfig(tool="gripper"), "RobotConfig.tool"),
    (lambda: RobotConfig(cup_radius=0.1), "RobotConfig.cup_radius"),
    (lambda: RobotConfig(home_q=(0.0,) * 5), "RobotConfig.home_q"),
    (lambda: RobotConfig(tool_tilt_deg=120.0), "RobotConfig.tool_tilt_deg"),
    (lambda: RobotConfig(approach="straight"), "RobotConfig.approach"),
    (lambda: GantryConfig(tool="gripper"), "GantryConfig.tool"),
    (lambda: GantryConfig(home_q=(0.0,) * 7), "GantryConfig.home_q"),
    (lambda: GantryConfig(lift_force=0.0), "GantryConfig.lift_force"),
])
def test_a_bad_robot_field_is_refused_by_name(make, field):
    with pytest.raises(ValueError, match=field):
        make()
