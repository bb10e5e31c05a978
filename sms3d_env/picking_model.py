"""The picking model: what happens to mushrooms between the tool and the soil, decided after
every physics substep (dm_control's ``after_substep``), apart from the gym API.

| rule | where | numbers |
| --- | --- | --- |
| what the tool holds and when it lets go (suction: seal, grip weld, grip loss; hand: fingers) | the tool, :mod:`sms3d_env.tools` (``Tool`` protocol) | see each tool |
| root detachment: the root's pull, bend and twist against their limits (a stiff weld, or with ``compliant_root`` a ball constraint and springs, :mod:`sms3d_env.roots`) | ``_check_roots`` | ``physics.root_utilisation`` |
| bruising: cap contact force above the threshold | ``_contacts`` | ``bruise_force`` |
| bruising by slip-shear (``slip_bruising``): friction work slipping on a cap | ``_slip_shear`` | ``slip_bruise_work`` |
| neighbours disturbed: moved further than the tolerance, or detached | ``after_step`` | ``disturb_tolerance`` |
| soil contacts of detached mushrooms once their stem is out of the soil | ``after_step`` | ``physics.SOIL_CLEARANCE`` |
| a released mushroom meets the casing at once (``stem_in_casing``): its cap the soil, its stem its hole's floor | ``after_step``, ``world.add_stem_sockets`` | |
| success: target detached, held, lifted, unbruised (with ``clean_pick``: no neighbour disturbed) | ``picked``, ``success`` | ``lift_height``, ``clean_pick`` |

Usage (what ``SMS3DPickEnv.step`` does)::

    model = PickingModel(world, params, target, reachable)   # the tool: world.tool's rules
    model.begin_step(action[6])          # the tool command for this control step
    for _ in range(substeps):
        mujoco.mj_step(world.model, world.data)
        if model.needs_substep_check():
            model.after_substep()
    model.after_step()
    info = model.evaluate(control_dt)
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from sms3d_env import physics as ph
from sms3d_env.episode_state import EpisodeState
from sms3d_env.physics_params import PickPhysicsParams
from sms3d_env.roots import CompliantRoots
from sms3d_env.tools import Tool, make_tool
from sms3d_env.world import World

FAILURE_CAUSES = ("not_reached", "no_seal", "grip_lost", "not_detached", "bruised", "neighbour_disturbed",
                  "unreachable", "timeout", "unstable_simulation", "seal_overloaded")
#: The tool "reached" the target once its site came this close to the true cap top (m): an
#: episode that never did fails as ``not_reached`` (the approach stopped short), not ``no_seal``.
REACHED_DISTANCE = 0.01
_EQ = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)


class PickingModel:
    """The picking rules of one episode on ``world``.

    Args:
        world: the episode's ``World`` (its model's contact masks and weld data change here).
        params: the picking model's numbers.
        target, reachable: the target mushroom and whether the IK reached it at reset.
        latched: the suction valve's training option (``Suction``'s ``latched``).
        roots: the world's compliant roots from an earlier pick in the same world (a harvest's
            next pick, ``SMS3DPickEnv.start_pick``): which roots still hold and their springs'
            state belong to the world, not to one pick. None: new ones, every free mushroom
            rooted as the world was built.

    ``tool`` holds the rules of ``world.tool`` (:mod:`sms3d_env.tools`). Call ``tool.reset()``
    before the world settles after reset, then ``settled()`` (it records the starting poses).
    """

    def __init__(self, world: World, params: PickPhysicsParams, target: int, reachable: bool,
                 latched: bool = False, roots: CompliantRoots | None = None) -> None:
        self.world, self.params = world, params
        self.state = EpisodeState(target=target, reachable=reachable)
        self.tool: Tool = make_tool(world, params, self.state, latched)
        if roots is None and params.compliant_root:
            roots = CompliantRoots(world, params)
        self.roots = roots
        self._qfrc = np.zeros(world.model.nv)
        self._vel6 = np.zeros(6)
        self.init_xpos = np.zeros((len(world.body_ids), 3))
        self.init_cap_top = np.zeros(3)

    @property
    def steps(self) -> int:
        """Control steps taken."""
        return self.state.steps

    def settled(self) -> None:
        d, w = self.world.data, self.world
        self.init_xpos = d.xpos[w.body_ids].copy()
        self.init_cap_top = d.site_xpos[w.cap_top_sites[self.state.target]].copy()

    # ------------------------------------------------------------------ per control step
    def begin_step(self, command: float) -> None:
        """The action's tool entry for the coming control step (``Tool.command``)."""
        ep = self.state
        ep.tool_on = self.tool.command(command)
        ep.root_util = 0.0

    def needs_substep_check(self) -> bool:
        """Whether ``after_substep`` has anything to decide (contacts, a grip, or the tool's
        hold to re-decide)."""
        return (self.tool.checks_every_substep or self.world.data.ncon > 0 or self.state.grip >= 0
                or (self.roots is not None and self.roots.any_active))

    def after_substep(self) -> None:
        """Bruises, the tool's hold and root loads from this physics step's contacts and welds."""
        ep, w, roots = self.state, self.world, self.roots
        touched, in_contact = self._contacts()
        self.tool.update_hold()
        if ep.grip >= 0:
            touched.add(ep.grip)
        if roots is not None:  # every root a contact loads, the robot's or a neighbour's
            roots.wake(in_contact | touched)
            roots.apply()
            touched = set(np.flatnonzero(roots.active).tolist())
        rooted = [k for k in touched if w.root_eq[k] >= 0 and w.data.eq_active[w.root_eq[k]]]
        if rooted:
            self._check_roots(rooted)
        self.tool.check_hold()

    def after_step(self) -> None:
        """End of a control step: the tool's rule (the hand: a lost grip), disturbed neighbours,
        detached mushrooms' soil contacts, the target's lift."""
        ep, w, d = self.state, self.world, self.world.data
        self.tool.after_step()
        ep.steps += 1
        if ep.grip_step < 0 and ep.ever_gripped_target:
            ep.grip_step = ep.steps
        if ep.detach_step < 0 and ep.target_detached:
            ep.detach_step = ep.steps
        gap = d.site_xpos[w.tool_site] - d.site_xpos[w.cap_top_sites[ep.target]]
        ep.closest_approach = min(ep.closest_approach, float(np.sqrt(gap @ gap)))
        # Only mushrooms with a free joint can move (the others are static bodies).
        free = w.free_ids
        moved = d.xpos[w.body_ids[free]] - self.init_xpos[free]
        for k in free[np.einsum("ij,ij->i", moved, moved) > self.params.disturb_tolerance**2]:
            if k != ep.target:
                ep.disturbed.add(int(k))
        ep.disturbed |= {k for k in ep.detached if k != ep.target}
        m = w.model
        for k in ep.detached:
            b, cap = w.body_ids[k], w.cap_geoms[k]
            if self.params.stem_in_casing and m.geom_conaffinity[cap] != w.lifted_aff:
                # The cap stands above the soil: it meets it from the moment the mushroom is
                # released (one that tips over lands on its cap) unless it already presses into it.
                self._set_soil_contact(k, True, (cap,))
                if self._penetrates_soil(k, cap):
                    self._set_soil_contact(k, False, (cap,))
            if m.geom_conaffinity[w.stem_geoms[k]] != w.lifted_aff and \
                    d.xpos[b, 2] - self.init_xpos[k, 2] > ph.SOIL_CLEARANCE:
                self._set_soil_contact(k, True)
                # Only once the stem's collision hull is out of the soil: switching contacts on
                # while it still penetrates (a sloped or tilted stem base) throws the mushroom
                # out of the cup.
                if self._penetrates_soil(k):
                    self._set_soil_contact(k, False)
        ep.max_lift = max(ep.max_lift, self.lift())

    # ------------------------------------------------------------------ contacts
    def _contacts(self) -> tuple[set[int], set[int]]:
        """Mushrooms the robot touches (each contact reported to the tool), and every mushroom in
        a contact; bruises."""
        w, ep, p = self.world, self.state, self.params
        m, d = w.model, w.data
        touched: set[int] = set()
        ncon = d.ncon
        if not ncon:
            return touched, set()
        geoms = d.contact.geom[:ncon]
        rows = np.nonzero((w.geom_mushroom[geoms] >= 0).any(axis=1))[0]
        in_contact = set(w.geom_mushroom[geoms[rows]].ravel().tolist()) - {-1}
        f6 = np.zeros(6)
        tool = self.tool
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
                    tool.on_contact(c, g, int(other), int(k), fn)
                if w.is_cap[g] and fn > p.bruise_force:
                    ep.bruised.add(int(k))
                if w.is_cap[g] and p.slip_bruising:
                    self._slip_shear(int(c), int(k), f6)
        return touched, in_contact

    def _slip_shear(self, contact: int, k: int, f6: np.ndarray) -> None:
        """Add one physics step's friction work slipping on cap ``k`` at ``contact`` (its force
        ``f6`` in the contact frame): the friction force times the relative tangential speed of
        the two surfaces there; a cap whose work reaches ``slip_bruise_work`` is bruised."""
        w, ep = self.world, self.state
        m, d = w.model, w.data
        friction = float(np.hypot(f6[1], f6[2]))
        if friction == 0.0:
            return
        point, frame = d.contact.pos[contact], d.contact.frame[contact].reshape(3, 3)
        g1, g2 = d.contact.geom[contact]
        relative = self._point_velocity(int(m.geom_bodyid[g1]), point) - self._point_velocity(int(m.geom_bodyid[g2]), point)
        slip = relative - (relative @ frame[0]) * frame[0]
        work = ep.slip_work.get(k, 0.0) + friction * float(np.linalg.norm(slip)) * m.opt.timestep
        ep.slip_work[k] = work
        if work >= self.params.slip_bruise_work:
            ep.bruised.add(k)

    def _point_velocity(self, body: int, point: np.ndarray) -> np.ndarray:
        """World linear velocity of the point of ``body`` at ``point`` (zero on the world body)."""
        if body == 0:
            return np.zeros(3)
        d = self.world.data
        mujoco.mj_objectVelocity(self.world.model, d, mujoco.mjtObj.mjOBJ_BODY, body, self._vel6, 0)
        return self._vel6[3:] + np.cross(self._vel6[:3], point - d.xpos[body])

    # ------------------------------------------------------------------ roots
    def _check_roots(self, ks: list[int]) -> None:
        w, ep = self.world, self.state
        m, d = w.model, w.data
        nefc = d.nefc
        eq = d.efc_type[:nefc] == _EQ
        rows = eq & w.is_root_eq[np.where(eq, d.efc_id[:nefc], 0)]
        q = ph.wrench_from_rows(m, d, rows, self._qfrc)
        for k in ks:
            rot = d.xmat[w.body_ids[k]].reshape(3, 3)
            force, torque = ph.free_body_wrench(q, w.dofadr[k], rot)
            axis = rot[:, 2]
            tension = max(0.0, -float(force @ axis))
            if self.roots is None:
                tw, bend = ph.axial_split(torque, axis)
            else:  # the ball constraint at the stem base holds no moment: the springs do
                bend, tw = self.roots.moments(k)
            u = ph.root_utilisation(tension, bend, abs(tw), self.params)
            if u >= 1.0:
                d.eq_active[w.root_eq[k]] = 0
                if self.roots is not None:
                    self.roots.release(k)
                for g in (w.cap_geoms[k], w.stem_geoms[k]):
                    m.geom_contype[g], m.geom_conaffinity[g] = ph.FREE_CONTYPE, w.free_aff
                b = w.body_ids[k]
                m.body_contype[b], m.body_conaffinity[b] = ph.FREE_CONTYPE, w.free_aff
                ep.detached.add(k)
                if k == ep.target:
                    ep.target_detached = True
            if k == ep.target:
                ep.root_util = max(ep.root_util, u)

    # ------------------------------------------------------------------ soil contacts
    def _set_soil_contact(self, k: int, on: bool, geoms: tuple[int, ...] | None = None) -> None:
        """Soil contacts of detached mushroom ``k``'s ``geoms`` (its cap and stem if None) on
        or off; its body's mask (the broadphase's) is the union of its geoms'."""
        w = self.world
        m = w.model
        aff = w.lifted_aff if on else w.free_aff
        for g in (w.cap_geoms[k], w.stem_geoms[k]) if geoms is None else geoms:
            m.geom_conaffinity[g] = aff
        m.body_conaffinity[w.body_ids[k]] = m.geom_conaffinity[w.cap_geoms[k]] | m.geom_conaffinity[w.stem_geoms[k]]

    def _penetrates_soil(self, k: int, geom: int | None = None) -> bool:
        """Whether mushroom ``k`` (its ``geom`` alone, if given) penetrates the soil now (runs
        the collision detector; the next physics step recomputes the contacts from scratch)."""
        w = self.world
        m, d = w.model, w.data
        mujoco.mj_collision(m, d)
        ncon = d.ncon
        if ncon == 0:
            return False
        geoms = d.contact.geom[:ncon]
        mine = ((w.geom_mushroom[geoms] == k) if geom is None else (geoms == geom)).any(axis=1) & \
            (geoms == w.terrain_geom).any(axis=1)
        return bool(np.any(d.contact.dist[:ncon][mine] < 0.0))

    # ------------------------------------------------------------------ outcome
    def lift(self) -> float:
        """Rise of the target's cap top since reset (m)."""
        w = self.world
        return float(w.data.site_xpos[w.cap_top_sites[self.state.target], 2] - self.init_cap_top[2])

    def picked(self) -> bool:
        """The target is off its roots, held and lifted: the pick is over, clean or not."""
        ep = self.state
        return bool(ep.target_detached and ep.grip == ep.target and not ep.unstable
                    and self.lift() >= self.params.lift_height)

    def success(self) -> bool:
        """Picked with no cap bruised; with ``clean_pick`` also no neighbour moved further than
        ``disturb_tolerance`` or knocked off its roots (a grower's clean pick)."""
        ep = self.state
        return self.picked() and not ep.bruised and not (self.params.clean_pick and ep.disturbed)

    def dead_end(self) -> bool:
        """The episode can no longer succeed (``Tool.dead_end``: suction, the target off its
        roots and not held, or a latched seal on another mushroom; the hand, never)."""
        return self.tool.dead_end()

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
            if ep.disturbed:
                return "neighbour_disturbed"
            return "no_seal" if ep.closest_approach <= REACHED_DISTANCE else "not_reached"
        if not ep.target_detached:
            # The seal let go under the twist or bend before the root did (a cup too weak for
            # the root, or a wrong axis bending it), or the root held through the whole twist.
            return "seal_overloaded" if ep.seal_overloaded else "not_detached"
        if ep.disturbed:
            return "neighbour_disturbed"
        return "timeout"

    def evaluate(self, control_dt: float) -> dict[str, Any]:
        """The episode's outcome so far (ManiSkill's ``evaluate()``): the env's ``info``;
        ``control_dt`` times its events (s since reset, None before they happen)."""
        ep = self.state
        success = self.success()
        return {
            "is_success": success,
            "failure_cause": None if success else self.failure_cause(),
            "target_picked": self.picked(),
            "target": ep.target,
            "reachable": ep.reachable,
            "gripped": ep.grip >= 0,
            "gripped_target": ep.grip == ep.target,
            "target_detached": ep.target_detached,
            "bruised": sorted(ep.bruised),
            "neighbours_disturbed": len(ep.disturbed),
            "lift": self.lift(),
            "unstable_simulation": ep.unstable,
            "time_s": round(ep.steps * control_dt, 9),
            "time_gripped_s": None if ep.grip_step < 0 else round(ep.grip_step * control_dt, 9),
            "time_detached_s": None if ep.detach_step < 0 else round(ep.detach_step * control_dt, 9),
        }
