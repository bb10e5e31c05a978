"""Picking physics: rooted mushrooms, root wrench and detachment, suction seal, grip, bruising.

All numbers live in ``PickPhysicsParams`` (:mod:`sms3d_env.physics_params`). Sources:
``docs/physics.md``; where it reports that no source exists, the default is an
ASSUMPTION and says so.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from sms3d_env.physics_params import PickPhysicsParams

# Collision bitmasks: soil 1, robot 2, mushroom 4, tool 8 (robot.py holds the robot's).
SOIL_CONTYPE, SOIL_CONAFFINITY = 1, 8  # the tool only; detached mushrooms via their conaffinity
ROOTED_CONTYPE, ROOTED_CONAFFINITY = 4, 2  # touch the robot only
# Detached: the robot, and the soil once clear of it (its stem base starts sunk in). KNOWN
# SIMPLIFICATION unless ``mushrooms_collide``: mushrooms do not collide with each other. The
# paper's placement lets two mushrooms' volumes overlap by up to 5 % (IoU), which leaves their
# collision hulls interpenetrating by up to 28 mm in 100-mushroom beds (measured); contacts
# switched on there throw the pair apart. Beds placed with no overlap start clear of each other.
FREE_CONTYPE, FREE_CONAFFINITY = 4, 2
LIFTED_CONAFFINITY = 1 | 2
# With ``PickPhysicsParams.mushrooms_collide`` every mushroom, rooted or loose, also collides with
# every other (this bit in each conaffinity); the bed's collision hulls must then not
# interpenetrate at rest (``world.interpenetrating_mushrooms``): beds placed with
# ``placement.overlap_iou = 0``.
MUSHROOM_CONTACT = ROOTED_CONTYPE
#: Deepest interpenetration (m) of two mushrooms' collision hulls a bed may start with when
#: mushrooms collide: deeper, and the contact would throw the pair apart at the first step.
MAX_REST_PENETRATION = 0.001
# Hand only: a static "socket" under each free mushroom's stem base holds it from below once it
# is detached (bit 16 on the socket, in the detached mushroom's conaffinity). A stem starts sunk
# 2-9 mm into the soil, so soil contacts wait for the lift; the suction cup holds a detached
# mushroom by its seal, but fingers closing on a cap detach it before they hold it.
SOCKET_CONTYPE = SOCKET_CONAFFINITY = 16
SOIL_CLEARANCE = 0.005  # m a detached mushroom must rise before it collides with the soil


def root_utilisation(tension: float, bend: float, twist: float, p: PickPhysicsParams) -> float:
    """Elliptic interaction of pull, bend and twist; >= 1 detaches."""
    return math.sqrt((tension / p.pull_force) ** 2 + (bend / p.bend_moment) ** 2
                     + (twist / p.twist_torque) ** 2)


def grip_utilisation(tension: float, shear: float, bend: float, twist: float,
                     p: PickPhysicsParams, compression: float = 0.0, vacuum_fraction: float = 1.0) -> float:
    """Load on the seal as a fraction of its capacity (>= 1 releases), elliptic interaction.

    Capacities: tension = holding force; shear = friction x normal force; bending moment =
    normal force x a / 2 (one rim edge lifts); twist = friction x normal force x 2a/3. The normal
    force pressing the lip on the cap is the holding force plus, with ``p.seal_preload``, the
    cup's ``compression`` of the cap (N), as in Dex-Net 3.0's suction contact model. The holding
    force is ``vacuum_fraction`` of the full vacuum's (the vacuum still rising after the seal).
    """
    fh, a, mu = p.holding_force * max(vacuum_fraction, 1e-9), p.cup_radius, p.shear_friction
    normal = fh + compression if p.seal_preload else fh
    return math.sqrt((tension / fh) ** 2 + (shear / (mu * normal)) ** 2 + (bend / (normal * a / 2)) ** 2
                     + (twist / (mu * normal * 2 * a / 3)) ** 2)


def wrench_from_rows(model: mujoco.MjModel, data: mujoco.MjData, rows: np.ndarray,
                     out: np.ndarray) -> np.ndarray:
    """Generalised force ``J^T f`` of the constraint rows ``rows`` (boolean mask over efc)."""
    f = np.where(rows, data.efc_force[: data.nefc], 0.0)
    mujoco.mj_mulJacTVec(model, data, out, f)
    return out


def free_body_wrench(qfrc: np.ndarray, dofadr: int, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World force and world torque (about the body origin) from a free joint's generalised force."""
    force = qfrc[dofadr : dofadr + 3]
    torque = rot @ qfrc[dofadr + 3 : dofadr + 6]
    return force, torque


def moment_about(force: np.ndarray, torque: np.ndarray, origin: np.ndarray,
                 point: np.ndarray) -> np.ndarray:
    """Moment about ``point`` of a wrench given as ``force`` and ``torque`` about ``origin``."""
    arm_x_force = np.empty(3)
    mujoco.mju_cross(arm_x_force, origin - point, force)  # np.cross costs ~10x more on 3-vectors
    return torque + arm_x_force


def axial_split(v: np.ndarray, axis: np.ndarray) -> tuple[float, float]:
    """Component of ``v`` along the unit ``axis``, and the magnitude of the rest of ``v``."""
    (vx, vy, vz), (ax, ay, az) = v.tolist(), axis.tolist()  # Python floats: no small-array calls
    along = vx * ax + vy * ay + vz * az
    return along, math.hypot(vx - along * ax, vy - along * ay, vz - along * az)


def weld_relpose(model: mujoco.MjModel, data: mujoco.MjData, body1: int, body2: int) -> np.ndarray:
    """Relative pose of body2 in body1's frame as MuJoCo weld data (pos 3, quat 4)."""
    r1 = data.xmat[body1].reshape(3, 3)
    pos = r1.T @ (data.xpos[body2] - data.xpos[body1])
    q1inv = np.zeros(4)
    mujoco.mju_negQuat(q1inv, data.xquat[body1])
    q = np.zeros(4)
    mujoco.mju_mulQuat(q, q1inv, data.xquat[body2])
    return np.concatenate([pos, q])
