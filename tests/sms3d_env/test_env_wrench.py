"""The grip/root wrench read from weld constraint forces: known loads, right point, right frame."""

import mujoco
import numpy as np
import pytest

from sms3d_env import physics as ph

_EQ = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)


def _welded_body(quat, com_offset):
    """A 50 g free body (rotated by ``quat``, COM off its origin) welded to the world."""
    spec = mujoco.MjSpec()
    spec.option.timestep = 0.002
    b = spec.worldbody.add_body(name="b", pos=[0.1, -0.2, 0.3], quat=quat)
    b.add_freejoint(name="j")
    b.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0], pos=com_offset, mass=0.05,
               contype=0, conaffinity=0)
    eq = spec.add_equality(name="w", type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY,
                           name1="b", name2="world")
    eq.data[:10] = 0.0
    eq.data[:3] = [0.1, -0.2, 0.3]  # anchor in body2's (the world's) frame: the body origin
    eq.solref = [0.004, 1.0]
    m = spec.compile()
    return m, mujoco.MjData(m)


@pytest.mark.parametrize("quat", [[1, 0, 0, 0], [0.8, 0.36, -0.48, 0.0]])
def test_weld_wrench_balances_known_load(quat):
    q = np.array(quat, float) / np.linalg.norm(quat)
    com_offset = np.array([0.0, 0.01, 0.04])  # like a cap 4 cm up the stem
    m, d = _welded_body(q, com_offset)
    b = m.body("b").id
    f_app = np.array([0.2, -0.1, 0.3])  # N at the COM (xfrc_applied acts at the COM, world frame)
    t_app = np.array([0.001, 0.0, -0.004])  # N m
    d.xfrc_applied[b] = np.r_[f_app, t_app]
    for _ in range(500):
        mujoco.mj_step(m, d)
    mujoco.mj_forward(m, d)
    qfrc = np.zeros(m.nv)
    rows = d.efc_type[: d.nefc] == _EQ
    ph.wrench_from_rows(m, d, rows, qfrc)
    rot = d.xmat[b].reshape(3, 3)
    force, torque = ph.free_body_wrench(qfrc, m.jnt_dofadr[0], rot)
    weight = m.body_mass[b] * m.opt.gravity
    total_f = f_app + weight
    com = d.xipos[b]
    # The weld holds the body still: its wrench cancels the applied load and the weight.
    np.testing.assert_allclose(force, -total_f, atol=1e-4)
    t_origin = t_app + np.cross(com - d.xpos[b], total_f)  # load moment about the body origin
    np.testing.assert_allclose(torque, -t_origin, atol=1e-5)
    # About a cup contact point 5 cm up the (rotated) body z axis.
    pc = d.xpos[b] + rot @ np.array([0.0, 0.0, 0.05])
    m_c = ph.moment_about(force, torque, d.xpos[b], pc)
    np.testing.assert_allclose(m_c, -(t_app + np.cross(com - pc, total_f)), atol=1e-5)


def test_env_grip_wrench_is_about_the_cup_contact():
    """A detached mushroom held by the cup alone, with a known extra load: the env's seal reading
    is the weight plus the load, and its moment is taken about the cup face, not the stem base."""
    import gymnasium as gym

    import generator
    import sms3d_env  # noqa: F401

    cfg = generator.SceneConfig().replace(placement__num_mushrooms=4)
    env = gym.make("SMS3DPick-v0", scene=cfg).unwrapped
    env.reset(seed=0)
    m, d = env.model, env.data
    k = env.picking.state.target
    b = env.world.body_ids[k]
    d.eq_active[env.world.root_eq[k]] = 0  # detached, and moved up to the cup
    qadr = m.jnt_qposadr[m.body_jntadr[b]]
    d.qpos[qadr : qadr + 3] += d.site_xpos[env.world.tool_site] - d.site_xpos[env.world.cap_top_sites[k]]
    mujoco.mj_forward(m, d)
    env.picking.tool.grip(k, d.site_xpos[env.world.tool_site].copy())  # sealed where the cup is now
    m.body_gravcomp[b] = 0.0
    f_app = np.array([0.1, 0.05, -0.2])
    d.xfrc_applied[b, :3] = f_app
    for _ in range(1500):
        mujoco.mj_step(m, d)
    mujoco.mj_forward(m, d)
    force, moment, z = env.picking.tool.grip_wrench()
    load = f_app + m.body_subtreemass[b] * m.opt.gravity
    np.testing.assert_allclose(force, -load, atol=2e-3)
    pc = d.site_xpos[env.world.tool_site]
    np.testing.assert_allclose(moment, -np.cross(d.xipos[b] - pc, load), atol=2e-4)
    np.testing.assert_allclose(z, d.site_xmat[env.world.tool_site].reshape(3, 3)[:, 2])
