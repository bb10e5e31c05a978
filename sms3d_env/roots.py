"""Compliant roots (``PickPhysicsParams.compliant_root``): a mushroom's stem base is pinned to the
casing by a ball constraint (MuJoCo ``connect``, stiff), and its stem bends and twists about that
point against rotational springs until the root fails.

| load | how it arises | fails at |
| --- | --- | --- |
| pull along the stem | the connect constraint's force | ``pull_force`` |
| bend about the stem base | spring ``bend_moment / bend_angle`` (N m/rad) on the bend angle | ``bend_moment``, i.e. after ``bend_angle_deg`` |
| twist about the stem | spring ``twist_torque / twist_angle`` on the twist angle | ``twist_torque``, i.e. after ``twist_angle_deg`` |

combined elliptically (``physics.root_utilisation``). The springs' rest state is the mushroom as
it grew: gravity is compensated while it is rooted (``body_gravcomp``), so a tilted mushroom
stands where it was placed. Damping (``root_damping_ratio`` of critical, on each rotational dof)
is integrated implicitly by MuJoCo's Euler integrator; the springs are applied explicitly
(``qfrc_applied``) after each physics step to the mushrooms that have been touched since reset
(the others are at rest: no deflection, no spring torque), so a bed at rest costs nothing.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from sms3d_env.physics_params import PickPhysicsParams
from sms3d_env.world import World

#: Largest ``omega dt`` (spring frequency x physics step, the inertia about the centre of mass)
#: the explicit springs are integrated with. A lone spring's semi-implicit Euler step is stable
#: below 2, but coupled to the soft ball constraint it is not: measured on a 15 g mushroom under
#: half its bending moment, the bend diverged at 1.0 and settled at the spring's angle at 0.5 and
#: 0.25 (as with a 1 ms step and no added inertia).
MAX_SPRING_STEP = 0.5


def rest_axis_angles(quat: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Rotation vectors (n, 3; rad, in the body frame) that turn each ``rest`` quaternion into
    ``quat`` (both (n, 4), w x y z): ``rest^-1 * quat`` as an axis times its angle."""
    w0, v0 = rest[:, :1], -rest[:, 1:]
    w1, v1 = quat[:, :1], quat[:, 1:]
    w = w0 * w1 - np.einsum("ij,ij->i", v0, v1)[:, None]
    v = w0 * v1 + w1 * v0 + np.cross(v0, v1)
    sign = np.where(w < 0, -1.0, 1.0)  # the shorter way round
    w, v = w * sign, v * sign
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    angle = 2.0 * np.arctan2(norm, w)
    return np.where(norm > 1e-12, v * (angle / np.maximum(norm, 1e-12)), 2.0 * v)


class CompliantRoots:
    """The root springs of one episode's world (built with ``world_spec(compliant_root=True)``,
    which compensates gravity; ``world.model`` is changed here: damping, the armature of mushrooms too light for the physics step to integrate their
    springs, ``MAX_SPRING_STEP``)."""

    def __init__(self, world: World, params: PickPhysicsParams) -> None:
        m = world.model
        self.world = world
        n = len(world.body_ids)
        bend_k = params.bend_moment / math.radians(params.bend_angle_deg)
        twist_k = params.twist_torque / math.radians(params.twist_angle_deg)
        self.stiffness = np.tile([bend_k, bend_k, twist_k], (n, 1))
        self.rooted = world.is_free.copy()
        self.active = np.zeros(n, bool)
        self.rest = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        self.rot_dofs = np.zeros((n, 3), int)
        self._deflection = np.zeros((n, 3))
        free = world.free_ids
        if not len(free):
            return
        joints = m.dof_jntid[world.dofadr[free]]
        self.rest[free] = m.qpos0[m.jnt_qposadr[joints][:, None] + np.arange(3, 7)]
        self.rot_dofs[free] = world.dofadr[free][:, None] + np.arange(3, 6)
        # Each spring's inertia along the body axes: about the centre of mass for the stability
        # bound (the ball constraint is soft over a physics step, so the fastest mode turns the
        # mushroom about its centre of mass: with the inertia about the stem base, bending
        # diverged within 0.5 s), about the stem base for the damping.
        com_inertia, base_inertia = np.empty((len(free), 3)), np.empty((len(free), 3))
        for row, k in enumerate(free):
            b = world.body_ids[k]
            rot = np.empty(9)
            mujoco.mju_quat2Mat(rot, m.body_iquat[b])
            rot = rot.reshape(3, 3)
            com = m.body_ipos[b]
            tensor = rot @ np.diag(m.body_inertia[b]) @ rot.T
            com_inertia[row] = np.diag(tensor)
            base_inertia[row] = np.diag(tensor + m.body_mass[b] * (com @ com * np.eye(3) - np.outer(com, com)))
        # The explicit springs need omega dt <= MAX_SPRING_STEP; the lightest mushrooms (5 g: a
        # twist inertia of 3e-7 kg m^2) would need a 0.5 ms step. They get rotational armature up
        # to the inertia that step can integrate instead: the springs' quasi-static loads (the
        # failure rule) are unchanged, and their dynamics are measured against a 4x finer step
        # in docs/physics.md.
        needed = self.stiffness[free] * (m.opt.timestep / MAX_SPRING_STEP) ** 2
        self.armature = np.zeros((n, 3))
        self.armature[free] = np.maximum(needed - com_inertia, 0.0)
        m.dof_armature[self.rot_dofs[free]] = self.armature[free]
        inertia = base_inertia + self.armature[free]
        damping = 2.0 * params.root_damping_ratio * np.sqrt(self.stiffness[free] * inertia)
        m.dof_damping[self.rot_dofs[free]] = damping

    @property
    def any_active(self) -> bool:
        """Whether some rooted mushroom has been touched since reset (its spring is live)."""
        return bool(self.active.any())

    def wake(self, ks) -> None:
        """Mushrooms ``ks`` were touched: their springs act from now on (while rooted)."""
        for k in ks:
            if self.rooted[k]:
                self.active[k] = True

    def apply(self) -> None:
        """Write the live springs' torques for the next physics step (``qfrc_applied``)."""
        ks = np.flatnonzero(self.active)
        if not len(ks):
            return
        w = self.world
        phi = rest_axis_angles(w.data.xquat[w.body_ids[ks]], self.rest[ks])
        self._deflection[ks] = phi
        w.data.qfrc_applied[self.rot_dofs[ks]] = -self.stiffness[ks] * phi

    def moments(self, k: int) -> tuple[float, float]:
        """Mushroom ``k``'s bending moment and twist torque at its root (N m) from its springs."""
        spring = self.stiffness[k] * self._deflection[k]
        return math.hypot(spring[0], spring[1]), abs(float(spring[2]))

    def angles_deg(self, k: int) -> tuple[float, float]:
        """Mushroom ``k``'s bend and twist at its root (deg) at the last ``apply``."""
        phi = self._deflection[k]
        return math.degrees(math.hypot(phi[0], phi[1])), math.degrees(abs(float(phi[2])))

    def release(self, k: int) -> None:
        """Mushroom ``k``'s root let go: no spring, no damping, full gravity."""
        w = self.world
        self.rooted[k] = self.active[k] = False
        w.data.qfrc_applied[self.rot_dofs[k]] = 0.0
        w.model.dof_damping[self.rot_dofs[k]] = 0.0
        w.model.dof_armature[self.rot_dofs[k]] = 0.0
        w.model.body_gravcomp[w.body_ids[k]] = 0.0
