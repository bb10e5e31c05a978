"""The picking model: what happens to mushrooms between the tool and the soil, decided after
every physics substep (dm_control's ``after_substep``), apart from the gym API.

| rule | where | numbers |
| --- | --- | --- |
| seal: cup on a cap top, within the seal angle, pressed with the seal force, suction on | ``PickingModel.seals`` / ``_contacts`` | ``PickPhysicsParams.seal_angle_deg``, ``seal_region``, ``seal_force`` |
| grip: the seal is a weld anchored at the contact; lost when its load exceeds capacity | ``grip`` / ``release`` / ``_check_grip`` | ``physics.grip_utilisation`` (vacuum x cup area, friction) |
| root detachment: the root weld's pull, bend and twist against their limits | ``_check_roots`` | ``physics.root_utilisation`` |
| bruising: cap contact force above the threshold | ``_contacts`` | ``bruise_force`` |
| neighbours disturbed: moved further than the tolerance, or detached | ``after_step`` | ``disturb_tolerance`` |
| soil contacts of detached mushrooms once their stem is out of the soil | ``after_step`` | ``physics.SOIL_CLEARANCE`` |
| success: target detached, held, lifted, unbruised | ``success`` | ``lift_height`` |

Usage (what ``SMS3DPickEnv.step`` does)::

    model = PickingModel(world, params, hand=None)
    model.begin_step(tool_on)            # the tool command for this control step
    for _ in range(substeps):
        mujoco.mj_step(world.model, world.data)
        model.after_substep()
    model.after_step()
    info = model.evaluate()
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from sms3d_env import physics as ph
from sms3d_env.hand import HandGrasp
from sms3d_env.physics_params import PickPhysicsParams
from sms3d_env.world import World

FAILURE_CAUSES = ("no_seal", "grip_lost", "not_detached", "bruised", "neighbour_disturbed",
                  "unreachable", "timeout", "unstable_simulation")
_EQ = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)


@dataclass
class EpisodeState:
    """What the picking model knows of the episode so far (mushroom ids index the scene)."""

    target: int = 0
    reachable: bool = True
    grip: int = -1  # mushroom id held (sealed by the cup, or pinched by the fingers), -1 if none
    grip_util: float = 0.0  # suction: seal load as a fraction of its capacity
    finger_force: float = 0.0  # hand: finger normal force on the target (N)
    tool_on: bool = False  # suction on, or hand commanded more closed than half
    ever_gripped_target: bool = False
    held_detached: bool = False  # hand: the target was held after its detachment
    finger_touch_step: int = -1  # hand: last env step in which a finger touched the target
    target_detached: bool = False
    grip_lost: bool = False
    bruised: set[int] = field(default_factory=set)
    detached: set[int] = field(default_factory=set)
    disturbed: set[int] = field(default_factory=set)
    unstable: bool = False
    max_lift: float = 0.0
    root_util: float = 0.0  # target root load / capacity, largest in this control step (reward only)
    seal_step: int = -1  # control step at which the current seal formed (-1: none)
    seal_tool_x: np.ndarray | None = None  # tool x axis (world) when it formed


class PickingModel:
    """The picking rules of one episode on ``world``.

    Args:
        world: the episode's ``World`` (its model's contact masks and weld data change here).
        params: the picking model's numbers.
        target, reachable: the target mushroom and whether the IK reached it at reset.
        hand: the hand's contact bookkeeping (``tool="hand"``), None for the suction cup.

    Call ``settled()`` once the world has settled after reset (it records the starting poses).
    """

    def __init__(self, world: World, params: PickPhysicsParams, target: int, reachable: bool,
                 hand: HandGrasp | None = None) -> None:
        self.world, self.params, self.hand = world, params, hand
        self.state = EpisodeState(target=target, reachable=reachable)
        self.steps = 0  # control steps taken
        self._qfrc = np.zeros(world.model.nv)
        self.init_xpos = np.zeros((len(world.body_ids), 3))
        self.init_cap_top = np.zeros(3)

    def settled(self) -> None:
        d, w = self.world.data, self.world
        self.init_xpos = d.xpos[w.body_ids].copy()
        self.init_cap_top = d.site_xpos[w.cap_top_sites[self.state.target]].copy()

    # ------------------------------------------------------------------ per control step
    def begin_step(self, tool_on: bool) -> None:
        """The tool command of the coming control step (suction: off releases the seal)."""
        ep = self.state
        ep.tool_on = tool_on
        ep.root_util = 0.0
        if self.hand is None and not tool_on and ep.grip >= 0:
            self.release()

    def needs_substep_check(self) -> bool:
        """Whether ``after_substep`` has anything to decide (contacts, a grip, or the hand)."""
        return self.hand is not None or self.world.data.ncon > 0 or self.state.grip >= 0

    def after_substep(self) -> None:
        """Seal, grip, bruises and root loads from this physics step's contacts and welds."""
        ep, w = self.state, self.world
        touched = self._contacts()
        if self.hand is not None:
            self._hand_grip()
        if ep.grip >= 0:
            touched.add(ep.grip)
        rooted = [k for k in touched if w.root_eq[k] >= 0 and w.data.eq_active[w.root_eq[k]]]
        if rooted:
            self._check_roots(rooted)
        if ep.grip >= 0 and self.hand is None:
            self._check_grip()

    def after_step(self) -> None:
        """End of a control step: the hand's lost grip, disturbed neighbours, detached
        mushrooms' soil contacts, the target's lift."""
        ep, w, d = self.state, self.world, self.world.data
        if ep.held_detached and ep.finger_touch_step < self.steps:
            ep.grip_lost = True  # hand: the detached target left the fingers for a whole step
        self.steps += 1
        # Only mushrooms with a free joint can move (the others are static bodies).
        free = w.free_ids
        moved = d.xpos[w.body_ids[free]] - self.init_xpos[free]
        for k in free[np.einsum("ij,ij->i", moved, moved) > self.params.disturb_tolerance**2]:
            if k != ep.target:
                ep.disturbed.add(int(k))
        ep.disturbed |= {k for k in ep.detached if k != ep.target}
        m = w.model
        for k in ep.detached:
            b = w.body_ids[k]
            if m.body_conaffinity[b] != w.lifted_aff and d.xpos[b, 2] - self.init_xpos[k, 2] > ph.SOIL_CLEARANCE:
                self._set_soil_contact(k, True)
                # Only once the stem's collision hull is out of the soil: switching contacts on
                # while it still penetrates (a sloped or tilted stem base) throws the mushroom
                # out of the cup.
                if self._penetrates_soil(k):
                    self._set_soil_contact(k, False)
        ep.max_lift = max(ep.max_lift, self.lift())

    # ------------------------------------------------------------------ contacts
    def _contacts(self) -> set[int]:
        """Mushrooms the robot touches; bruises; the seal test on cup-cap contacts."""
        w, ep, p = self.world, self.state, self.params
        m, d = w.model, w.data
        touched: set[int] = set()
        ncon = d.ncon
        if not ncon:
            return touched
        geoms = d.contact.geom[:ncon]
        rows = np.nonzero((w.geom_mushroom[geoms] >= 0).any(axis=1))[0]
        f6 = np.zeros(6)
        for c in rows:
            g1, g2 = geoms[c]
            mujoco.mj_contactForce(m, d, int(c), f6)
            fn = abs(f6[0])
            for g, other in ((g1, g2), (g2, g1)):
                k = w.geom_mushroom[g]
                if k < 0:
                    continue
                if w.robot_geom[other]:
                    touched.add(int(k))
                    if self.hand is not None:
                        self.hand.add(int(other), int(k), fn)
                if w.is_cap[g] and fn > p.bruise_force:
                    ep.bruised.add(int(k))
                if (other == w.cup_geom and w.is_cap[g] and ep.tool_on
                        and ep.grip < 0 and fn >= p.seal_force and w.grip_eq[k] >= 0):
                    normal = d.contact.frame[c][:3] * (1.0 if g1 == w.cup_geom else -1.0)
                    if self.seals(int(k), d.contact.pos[c], normal):
                        self.grip(int(k), d.contact.pos[c].copy())
        return touched

    def _hand_grip(self) -> None:
        """Hand: what the fingers hold after this physics step (held = at least two fingers on
        it while the hand is commanded closed), then forget the step's contacts."""
        ep, hand = self.state, self.hand
        ep.grip = hand.held(ep.target) if ep.tool_on else -1
        ep.finger_force = hand.force.get(ep.target, 0.0)
        if ep.target in hand.fingers:
            ep.finger_touch_step = self.steps
        if ep.grip == ep.target:
            ep.ever_gripped_target = True
            ep.held_detached |= ep.target_detached
        hand.clear()

    # ------------------------------------------------------------------ seal and grip
    def seals(self, k: int, point: np.ndarray, normal_cup_to_cap: np.ndarray) -> bool:
        """Seal test: cup axis vs. cap normal at the contact, and contact on the cap top."""
        w, p = self.world, self.params
        d = w.data
        z = d.site_xmat[w.tool_site].reshape(3, 3)[:, 2]
        cos = float(z @ normal_cup_to_cap)
        if cos < np.cos(np.deg2rad(p.seal_angle_deg)):
            return False
        b = w.body_ids[k]
        axis = d.xmat[b].reshape(3, 3)[:, 2]
        rel = point - d.xpos[b]
        radial = np.linalg.norm(rel - (rel @ axis) * axis)
        return bool(radial <= p.seal_region * w.cap_radius[k])

    def grip(self, k: int, point: np.ndarray | None = None) -> None:
        """Seal the cup on mushroom ``k``: a weld anchored at the contact ``point`` (world;
        default the tool site)."""
        w, ep = self.world, self.state
        m, d = w.model, w.data
        e, b = w.grip_eq[k], w.body_ids[k]
        point = np.asarray(d.site_xpos[w.tool_site] if point is None else point, float)
        # Anchor (body2 = mushroom frame) at the cup-cap contact: the weld is the seal itself.
        # MuJoCo's weld joins the point eq_data[:3] in body2's frame to the point eq_data[3:6] in
        # body1's (the cup's) frame: both are the contact point now; eq_data[6:10] is the
        # relative orientation.
        m.eq_data[e, :3] = d.xmat[b].reshape(3, 3).T @ (point - d.xpos[b])
        m.eq_data[e, 3:10] = ph.weld_relpose(m, d, w.cup_body, b)
        m.eq_data[e, 3:6] = d.xmat[w.cup_body].reshape(3, 3).T @ (point - d.xpos[w.cup_body])
        m.eq_data[e, 10] = 1.0
        d.eq_active[e] = 1
        # While sealed, the weld is the cup-cap interface: the cup face stops colliding with
        # mushrooms (otherwise contact and weld fight and load the seal with internal forces).
        m.geom_conaffinity[w.cup_geom] = 0
        m.geom_contype[w.cup_geom] = ph.SOIL_CONAFFINITY
        ep.grip = k
        ep.seal_step, ep.seal_tool_x = self.steps, d.site_xmat[w.tool_site, 0::3].copy()
        if k == ep.target:
            ep.ever_gripped_target = True

    def release(self) -> None:
        w, ep = self.world, self.state
        w.data.eq_active[w.grip_eq[ep.grip]] = 0
        w.model.geom_contype[w.cup_geom], w.model.geom_conaffinity[w.cup_geom] = w.cup_mask
        ep.grip, ep.grip_util, ep.seal_step, ep.seal_tool_x = -1, 0.0, -1, None

    def _eq_wrench(self, rows: np.ndarray) -> np.ndarray:
        return ph.wrench_from_rows(self.world.model, self.world.data, rows, self._qfrc)

    def _check_roots(self, ks: list[int]) -> None:
        w, ep = self.world, self.state
        m, d = w.model, w.data
        nefc = d.nefc
        eq = d.efc_type[:nefc] == _EQ
        rows = eq & w.is_root_eq[np.where(eq, d.efc_id[:nefc], 0)]
        q = self._eq_wrench(rows)
        for k in ks:
            rot = d.xmat[w.body_ids[k]].reshape(3, 3)
            force, torque = ph.free_body_wrench(q, w.dofadr[k], rot)
            axis = rot[:, 2]
            tension = max(0.0, -float(force @ axis))
            tw, bend = ph.axial_split(torque, axis)
            u = ph.root_utilisation(tension, bend, abs(tw), self.params)
            if u >= 1.0:
                d.eq_active[w.root_eq[k]] = 0
                for g in (w.cap_geoms[k], w.stem_geoms[k]):
                    m.geom_contype[g], m.geom_conaffinity[g] = ph.FREE_CONTYPE, w.free_aff
                b = w.body_ids[k]
                m.body_contype[b], m.body_conaffinity[b] = ph.FREE_CONTYPE, w.free_aff
                ep.detached.add(k)
                if k == ep.target:
                    ep.target_detached = True
            if k == ep.target:
                ep.root_util = max(ep.root_util, u)

    def grip_wrench(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Load the seal carries: world force the cup exerts on the gripped mushroom, its moment
        about the cup contact point (the tool site on the cup face), and the cup axis."""
        w, k = self.world, self.state.grip
        d = w.data
        nefc = d.nefc
        rows = (d.efc_type[:nefc] == _EQ) & (d.efc_id[:nefc] == w.grip_eq[k])  # eq ids only
        q = self._eq_wrench(rows)
        b = w.body_ids[k]
        force, torque = ph.free_body_wrench(q, w.dofadr[k], d.xmat[b].reshape(3, 3))
        moment = ph.moment_about(force, torque, d.xpos[b], d.site_xpos[w.tool_site])
        return force, moment, d.site_xmat[w.tool_site].reshape(3, 3)[:, 2].copy()

    def _check_grip(self) -> None:
        ep = self.state
        k = ep.grip
        force, torque_c, z = self.grip_wrench()
        fz, shear = ph.axial_split(force, z)
        tz, bend = ph.axial_split(torque_c, z)
        u = ph.grip_utilisation(max(0.0, -fz), shear, bend, abs(tz), self.params)
        ep.grip_util = u
        if u >= 1.0:
            if k == ep.target and ep.target_detached:
                ep.grip_lost = True
            self.release()

    # ------------------------------------------------------------------ soil contacts
    def _set_soil_contact(self, k: int, on: bool) -> None:
        w = self.world
        aff = w.lifted_aff if on else w.free_aff
        for g in (w.cap_geoms[k], w.stem_geoms[k]):
            w.model.geom_conaffinity[g] = aff
        w.model.body_conaffinity[w.body_ids[k]] = aff

    def _penetrates_soil(self, k: int) -> bool:
        """Whether mushroom ``k`` penetrates the soil now (runs the collision detector; the
        next physics step recomputes the contacts from scratch)."""
        w = self.world
        m, d = w.model, w.data
        mujoco.mj_collision(m, d)
        ncon = d.ncon
        if ncon == 0:
            return False
        geoms = d.contact.geom[:ncon]
        mine = (w.geom_mushroom[geoms] == k).any(axis=1) & (geoms == w.terrain_geom).any(axis=1)
        return bool(np.any(d.contact.dist[:ncon][mine] < 0.0))

    # ------------------------------------------------------------------ outcome
    def lift(self) -> float:
        """Rise of the target's cap top since reset (m)."""
        w = self.world
        return float(w.data.site_xpos[w.cap_top_sites[self.state.target], 2] - self.init_cap_top[2])

    def success(self) -> bool:
        ep = self.state
        return bool(ep.target_detached and ep.grip == ep.target and not ep.bruised
                    and not ep.unstable and self.lift() >= self.params.lift_height)

    def dead_end(self, latched: bool) -> bool:
        """The episode can no longer succeed: the target is off its roots and not held (suction;
        the hand detaches a cap as its fingers close, before it holds it), or a ``latched``
        seal holds another mushroom."""
        ep = self.state
        if self.hand is not None:
            return False
        knocked_off = ep.target_detached and ep.grip != ep.target
        wrong_seal = latched and ep.grip >= 0 and ep.grip != ep.target
        return knocked_off or wrong_seal

    def failure_cause(self) -> str | None:
        """Why the episode is not (yet) a success (one of ``FAILURE_CAUSES``), or None."""
        ep = self.state
        if self.success():
            return None
        if ep.unstable:
            return "unstable_simulation"
        if not ep.reachable:
            return "unreachable"
        if ep.bruised:
            return "bruised"
        if ep.grip_lost:
            return "grip_lost"
        if not ep.ever_gripped_target:
            return "neighbour_disturbed" if ep.disturbed else "no_seal"
        if not ep.target_detached:
            return "not_detached"
        if ep.disturbed:
            return "neighbour_disturbed"
        return "timeout"

    def evaluate(self) -> dict[str, Any]:
        """The episode's outcome so far (ManiSkill's ``evaluate()``): the env's ``info``."""
        ep = self.state
        success = self.success()
        return {
            "is_success": success,
            "failure_cause": None if success else self.failure_cause(),
            "target": ep.target,
            "reachable": ep.reachable,
            "gripped": ep.grip >= 0,
            "gripped_target": ep.grip == ep.target,
            "target_detached": ep.target_detached,
            "bruised": sorted(ep.bruised),
            "neighbours_disturbed": len(ep.disturbed),
            "lift": self.lift(),
            "unstable_simulation": ep.unstable,
        }
