"""The Jaco 3-finger hand in an assembled env model: finger commands, closure, finger contacts.

The hand holds a mushroom by MuJoCo contact friction alone (no weld, no seal model). A mushroom
counts as *held* while at least ``MIN_FINGERS`` fingers touch it; the env collects the contacts
after each physics step (``clear``, then ``add`` per contact, then ``held``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import mujoco
import numpy as np

from sms3d_env.physics import SOCKET_CONTYPE
from sms3d_env.robot import FINGER_BODIES, FINGER_JOINTS, PREFIX

MIN_FINGERS = 2  # a thumb against one finger already pinches; one finger alone only pushes


class HandGrasp:
    """Finger joints, actuators and contact bookkeeping of the hand in ``model``."""

    def __init__(self, model: mujoco.MjModel) -> None:
        ids = [model.joint(PREFIX + j).id for j in FINGER_JOINTS]
        self.qadr = model.jnt_qposadr[ids]
        self.lo, self.hi = model.jnt_range[ids, 0], model.jnt_range[ids, 1]
        self.act = np.array([model.actuator(PREFIX + f"act_{j}").id for j in FINGER_JOINTS])
        # Finger index (0-2) of every geom on a finger's proximal or distal body, else -1.
        self.finger_of_geom = np.full(model.ngeom, -1)
        for f, bodies in enumerate(FINGER_BODIES):
            for name in bodies:
                self.finger_of_geom[model.geom_bodyid == model.body(PREFIX + name).id] = f
        self.clear()

    def open(self, data: mujoco.MjData) -> None:
        """Fingers fully open, and commanded to stay so."""
        data.qpos[self.qadr] = self.lo
        data.ctrl[self.act] = self.lo

    def command(self, data: mujoco.MjData, a: float) -> None:
        """``a`` in [-1, 1]: -1 fully open, +1 fully closed, linear in joint angle between."""
        data.ctrl[self.act] = self.lo + 0.5 * (a + 1.0) * (self.hi - self.lo)

    def closure(self, data: mujoco.MjData) -> float:
        """Measured closure, 0 (open) to 1 (closed), mean over the fingers."""
        return float(np.mean((data.qpos[self.qadr] - self.lo) / (self.hi - self.lo)))

    def clear(self) -> None:
        """Forget the contacts of the previous physics step."""
        self.fingers: dict[int, int] = {}  # mushroom -> bit set of touching fingers
        self.force: dict[int, float] = {}  # mushroom -> summed finger normal force (N)

    def add(self, geom: int, mushroom: int, normal_force: float) -> None:
        """Record a contact between robot ``geom`` and ``mushroom`` (ignored unless a finger)."""
        f = int(self.finger_of_geom[geom])
        if f >= 0:
            self.fingers[mushroom] = self.fingers.get(mushroom, 0) | (1 << f)
            self.force[mushroom] = self.force.get(mushroom, 0.0) + normal_force

    def held(self, prefer: int) -> int:
        """A mushroom touched by at least ``MIN_FINGERS`` fingers (``prefer`` if it is), or -1."""
        held = [k for k, bits in self.fingers.items() if bits.bit_count() >= MIN_FINGERS]
        if not held:
            return -1
        return prefer if prefer in held else max(held, key=lambda k: self.force[k])


def add_stem_sockets(spec: mujoco.MjSpec, scene: Any, ids: Iterable[int], drop: float = 0.001) -> None:
    """A thin static box ``drop`` below the lowest point of each listed mushroom's stem, felt
    only by detached mushrooms (``physics.SOCKET_CONTYPE``): the casing around the stem base that
    holds a detached mushroom up until it is lifted out of its hole."""
    for i in ids:
        inst = scene.instances[i]
        local = np.asarray(inst.model.stem_mesh.vertices) * inst.scale_vector
        world = local @ np.asarray(inst.rotation).T + inst.position
        half = float(np.hypot(local[:, 0], local[:, 1]).max()) + 0.002
        spec.worldbody.add_geom(
            name=f"socket_{i}", type=mujoco.mjtGeom.mjGEOM_BOX, size=[half, half, 0.002],
            pos=[inst.position[0], inst.position[1], world[:, 2].min() - drop - 0.002],
            contype=SOCKET_CONTYPE, conaffinity=0, group=4, rgba=[0.4, 0.3, 0.2, 0])
