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

