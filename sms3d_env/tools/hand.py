"""The Jaco 3-finger hand's rules: finger commands and closure, finger contacts, what it holds.

The hand holds a mushroom by MuJoCo contact friction alone (no weld, no seal model). A mushroom
counts as *held* while at least ``MIN_FINGERS`` fingers touch it with the hand commanded closed;
the picking model reports each physics step's finger contacts (``on_contact``), then asks what is
held (``update_hold``). Fingers closing on a cap detach it before they hold it, so the hand has no
dead end; a detached target that leaves the fingers for a whole control step is a lost grip.
What holds a detached mushroom up until it is lifted is the world's: the stem sockets that
``world.world_spec`` adds with the hand (``world.add_stem_sockets``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from sms3d_env.robot import FINGER_BODIES, FINGER_JOINTS

if TYPE_CHECKING:
    from sms3d_env.episode_state import EpisodeState
    from sms3d_env.physics_params import PickPhysicsParams
    from sms3d_env.world import World

MIN_FINGERS = 2  # a thumb against one finger already pinches; one finger alone only pushes


class Hand:
    """Finger joints, actuators and contact bookkeeping of the hand in one episode's ``world``
    (``params`` unused: the hand's numbers are the robot's, ``RobotConfig``)."""

    name = "hand"
    checks_every_substep = True

    def __init__(self, world: World, params: PickPhysicsParams | None, state: EpisodeState) -> None:
        self.world, self.state = world, state
        model = world.model
        prefix = world.prefix
        ids = [model.joint(prefix + j).id for j in FINGER_JOINTS]
        self.qadr = model.jnt_qposadr[ids]
        self.lo, self.hi = model.jnt_range[ids, 0], model.jnt_range[ids, 1]
        self.act = np.array([model.actuator(prefix + f"act_{j}").id for j in FINGER_JOINTS])
        # Finger index (0-2) of every geom on a finger's proximal or distal body, else -1.
        self.finger_of_geom = np.full(model.ngeom, -1)
        for f, bodies in enumerate(FINGER_BODIES):
            for name in bodies:
                self.finger_of_geom[model.geom_bodyid == model.body(prefix + name).id] = f
        self.clear()

    # ------------------------------------------------------------------ fingers
    def reset(self) -> None:
        """Fingers fully open, and commanded to stay so."""
        data = self.world.data
        data.qpos[self.qadr] = self.lo
        data.ctrl[self.act] = self.lo

    def command(self, a: float) -> bool:
        """``a`` in [-1, 1]: -1 fully open, +1 fully closed, linear in joint angle between;
        the hand counts as closed (on) for ``a`` > 0."""
        self.world.data.ctrl[self.act] = self.lo + 0.5 * (a + 1.0) * (self.hi - self.lo)
        return a > 0

    def closure(self) -> float:
        """Measured closure, 0 (open) to 1 (closed), mean over the fingers."""
        return float(np.mean((self.world.data.qpos[self.qadr] - self.lo) / (self.hi - self.lo)))

    # ------------------------------------------------------------------ contacts and hold
    def clear(self) -> None:
        """Forget the contacts of the previous physics step."""
        self.fingers: dict[int, int] = {}  # mushroom -> bit set of touching fingers
        self.force: dict[int, float] = {}  # mushroom -> summed finger normal force (N)

    def on_contact(self, contact: int, geom: int, robot_geom: int, mushroom: int,
                   normal_force: float) -> None:
        """Record a contact between ``robot_geom`` and ``mushroom`` (ignored unless a finger)."""
        f = int(self.finger_of_geom[robot_geom])
        if f >= 0:
            self.fingers[mushroom] = self.fingers.get(mushroom, 0) | (1 << f)
            self.force[mushroom] = self.force.get(mushroom, 0.0) + normal_force

    def held(self, prefer: int) -> int:
        """A mushroom touched by at least ``MIN_FINGERS`` fingers (``prefer`` if it is), or -1."""
        held = [k for k, bits in self.fingers.items() if bits.bit_count() >= MIN_FINGERS]
        if not held:
            return -1
        return prefer if prefer in held else max(held, key=lambda k: self.force[k])

    def update_hold(self) -> None:
        """What the fingers hold after this physics step (held = at least two fingers on it
        while the hand is commanded closed), then forget the step's contacts."""
        ep = self.state
        ep.grip = self.held(ep.target) if ep.tool_on else -1
        ep.finger_force = self.force.get(ep.target, 0.0)
        if ep.target in self.fingers:
            ep.finger_touch_step = ep.steps
        if ep.grip == ep.target:
            ep.ever_gripped_target = True
            ep.held_detached |= ep.target_detached
        self.clear()

    def check_hold(self) -> None:
        pass  # friction holds or slips in MuJoCo's contacts

    # ------------------------------------------------------------------ episode
    def after_step(self) -> None:
        ep = self.state
        if ep.held_detached and ep.finger_touch_step < ep.steps:
            ep.grip_lost = True  # the detached target left the fingers for a whole step

    def dead_end(self) -> bool:
        return False  # the fingers detach a cap as they close, before they hold it

    def observation(self) -> tuple[float, float, float]:
        """(closure 0-1, holding with >= 2 fingers, finger force on the target N)."""
        ep = self.state
        return self.closure(), float(ep.grip >= 0), ep.finger_force
