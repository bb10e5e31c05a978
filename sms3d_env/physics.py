"""Picking physics: rooted mushrooms, root wrench and detachment, suction seal, grip, bruising.

All numbers live in ``PickPhysicsParams``. Sources: ``shared/reference/harvest-physics.md``; where
it reports that no source exists, the default is an ASSUMPTION and says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

# Collision bitmasks: soil 1, robot 2, mushroom 4, tool 8 (robot.py holds the robot's).
SOIL_CONTYPE, SOIL_CONAFFINITY = 1, 8  # the tool only; detached mushrooms via their conaffinity
ROOTED_CONTYPE, ROOTED_CONAFFINITY = 4, 2  # touch the robot only
# Detached: the robot, and the soil once clear of it (its stem base starts sunk in). KNOWN
# SIMPLIFICATION: a detached mushroom does not collide with other mushrooms. MuJoCo collides mesh
# geoms through their convex hulls, and in clusters the hulls of touching caps overlap by several
# millimetres (the real meshes do not, see the placement overlap test): switching those contacts on
# at detachment throws the pair apart with 10 N. Neighbours are still disturbed by the tool.
FREE_CONTYPE, FREE_CONAFFINITY = 4, 2
LIFTED_CONAFFINITY = 1 | 2
# Hand only: a static "socket" under each free mushroom's stem base holds it from below once it
# is detached (bit 16 on the socket, in the detached mushroom's conaffinity). A stem starts sunk
# 2-9 mm into the soil, so soil contacts wait for the lift; the suction cup holds a detached
# mushroom by its seal, but fingers closing on a cap detach it before they hold it.
SOCKET_CONTYPE = SOCKET_CONAFFINITY = 16
SOIL_CLEARANCE = 0.005  # m a detached mushroom must rise before it collides with the soil


@dataclass(frozen=True)
class PickPhysicsParams:
    """Parameters of the picking model.

    Attributes:
        pull_force: axial tension at the root that detaches a mushroom (N). ASSUMPTION (no source
            for pull-off force): above the suction holding force, so a straight pull loses the
            grip first, as "twist, do not pull" and every documented method imply.
        bend_moment: bending moment at the root that detaches (N m). ASSUMPTION (no source):
            about 2 N of side force on a cap 4 cm above the root, 8x what gravity gives a 50 g
            mushroom tilted by 30 degrees. It exceeds the seal's bending capacity (holding force
            x a / 2 = 0.031 N m), so bending alone loses the grip before it detaches, as the
            twist-first methods in harvest-physics.md imply. (0.02 N m, the earlier value, is
            0.5 N at the cap: a cup's approach alone uprooted mushrooms.)
        twist_torque: torque about the stem that detaches (N m). ASSUMPTION (no source); twisting
            detaches most easily, as pickers are told ("twist, do not pull").
        vacuum: suction vacuum (Pa), 20 kPa as in harvest-physics.md.
        cup_radius: cup radius (m), 10 mm (a 20 mm cup) as in harvest-physics.md.
        seal_angle_deg: largest angle between the cup axis and the cap surface normal at the
            contact that still seals. ASSUMPTION: a 10 mm cup tilted 20 degrees lifts one rim edge
            by 2a sin(20) = 6.8 mm (harvest-physics.md [derived]), about a bellows stroke.
        seal_region: the contact must lie within this fraction of the cap radius from the stem
            axis (the cap top, not its softer, curved rim). ASSUMPTION.
        seal_force: cup-on-cap normal force needed to form a seal (N). ASSUMPTION.
        shear_friction: shear capacity of the seal as a fraction of the holding force.
            ASSUMPTION (rubber on a moist cap).
        bruise_force: cap contact normal force that bruises (N). ASSUMPTION: harvest-physics.md
            reports no numeric bruising threshold.
        disturb_tolerance: a neighbour moved further than this (m) counts as disturbed. ASSUMPTION.
        lift_height: height the target must be lifted above its starting cap top (m). ASSUMPTION.
        settle_time: simulated seconds after reset before detachment is checked (the soft welds
            take up gravity).
    """

    pull_force: float = 8.0
    bend_moment: float = 0.08
    twist_torque: float = 0.006
    vacuum: float = 20e3
    cup_radius: float = 0.010
    seal_angle_deg: float = 20.0
    seal_region: float = 0.5
    seal_force: float = 0.3
    shear_friction: float = 0.5
    bruise_force: float = 25.0
    disturb_tolerance: float = 0.005
    lift_height: float = 0.03
    settle_time: float = 0.1

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"PickPhysicsParams.{name} must be a finite number >= 0, got {value!r}")
        if not 0 < self.seal_angle_deg < 90:
            raise ValueError("PickPhysicsParams.seal_angle_deg must be in (0, 90)")

    @property
    def holding_force(self) -> float:
        """Suction holding force = vacuum x cup area (N); 6.3 N with the defaults."""
        return self.vacuum * math.pi * self.cup_radius**2


def root_utilisation(tension: float, bend: float, twist: float, p: PickPhysicsParams) -> float:
    """Elliptic interaction of pull, bend and twist; >= 1 detaches."""
    return math.sqrt((tension / p.pull_force) ** 2 + (bend / p.bend_moment) ** 2
                     + (twist / p.twist_torque) ** 2)


def grip_utilisation(tension: float, shear: float, bend: float, twist: float,
                     p: PickPhysicsParams) -> float:
    """Load on the seal as a fraction of its capacity (>= 1 releases), elliptic interaction.

    Capacities: tension = holding force; shear = friction x holding force; bending moment =
    holding force x a / 2 (one rim edge lifts); twist = friction x holding force x 2a/3.
    """
    fh, a, mu = p.holding_force, p.cup_radius, p.shear_friction
    return math.sqrt((tension / fh) ** 2 + (shear / (mu * fh)) ** 2 + (bend / (fh * a / 2)) ** 2
                     + (twist / (mu * fh * 2 * a / 3)) ** 2)


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
