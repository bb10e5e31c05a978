"""The suction tool's rules: the valve, the seal, the grip weld and its loss.

| rule | where | numbers |
| --- | --- | --- |
| valve: on while the command is > 0; latched (training option): held once sealed | ``Suction.command`` | |
| seal: cup on a cap top, within the seal angle, pressed with the seal force, suction on | ``on_contact`` / ``seals`` | ``PickPhysicsParams.seal_angle_deg``, ``seal_region``, ``seal_force`` |
| seal on the whole lip (``lip_seal``): every lip point over the target's cap within the lip's compliance | ``lip_gaps`` | ``PickPhysicsParams.lip_compliance``, ``lip_points`` |
| vacuum rise (``lip_seal``): the holding force grows over the evacuation time | ``check_hold`` | ``PickPhysicsParams.evacuation_time`` |
| grip: the seal is a weld anchored at the contact; released when the valve closes | ``grip`` / ``release`` | |
| grip loss: the seal's load (low-passed) against its capacity | ``check_hold`` / ``grip_wrench`` | ``physics.grip_utilisation`` (vacuum x cup area, friction), ``PickPhysicsParams.seal_response_time`` |
| dead ends: the target knocked off its roots and not held, or a latched seal on a neighbour | ``dead_end`` | |
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from sms3d_env import physics as ph
from sms3d_env.physics_params import PickPhysicsParams

if TYPE_CHECKING:
    from sms3d_env.episode_state import EpisodeState
    from sms3d_env.world import World

_EQ = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)
#: The lip test's rays start this far behind the cup face (m), beyond how deep the soft cup-cap
#: contact lets the face sink into the cap, so that no ray starts inside the cap.
LIP_RAY_SETBACK = 0.005


class Suction:
    """The suction cup of one episode on ``world`` (its grip welds and cup ids).

    Args:
        world, params, state: the episode's world, picking numbers and state.
        latched: the vacuum valve holds its state: once a seal forms it stays on whatever the
            command (``suction_mode="latched"``), as a picker's valve does after its vacuum
            switch trips.
    """

    name = "suction"
    checks_every_substep = False

    def __init__(self, world: World, params: PickPhysicsParams, state: EpisodeState,
                 latched: bool = False) -> None:
        self.world, self.params, self.state, self.latched = world, params, state, latched
        self._qfrc = np.zeros(world.model.nv)
        # The seal answers its load over its response time, not one physics step's impulse
        # (which grows as the step shrinks): a first-order low-pass, exact for any step size,
        # whose weight per physics step is fixed by the world's step.
        tau = params.seal_response_time
        self._load_blend = 1.0 - math.exp(-world.model.opt.timestep / tau) if tau > 0 else 1.0
        angles = np.linspace(0.0, 2 * np.pi, int(params.lip_points), endpoint=False)
        self._lip_offsets = params.cup_radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
        self._ray_geom = np.zeros(1, np.int32)
        self._seal_time = 0.0

    def reset(self) -> None:
        pass

    def command(self, a: float) -> bool:
        """Suction on if ``a`` > 0 (latched: also while a seal holds); off releases the seal."""
        ep = self.state
        on = a > 0 or (self.latched and ep.grip >= 0)
        if not on and ep.grip >= 0:
            self.release()
        return on

    # ------------------------------------------------------------------ seal
    def on_contact(self, contact: int, geom: int, robot_geom: int, mushroom: int,
                   normal_force: float) -> None:
        """The seal test on a cup-cap contact while suction is on and nothing is held."""
        w, ep, p = self.world, self.state, self.params
        if (robot_geom == w.cup_geom and w.is_cap[geom] and ep.tool_on
                and ep.grip < 0 and normal_force >= p.seal_force and w.grip_eq[mushroom] >= 0):
            d = w.data
            normal = d.contact.frame[contact][:3] * (1.0 if d.contact.geom[contact][0] == w.cup_geom else -1.0)
            if self.seals(mushroom, d.contact.pos[contact], normal):
                self.grip(mushroom, d.contact.pos[contact].copy())

    def seals(self, k: int, point: np.ndarray, normal_cup_to_cap: np.ndarray) -> bool:
        """Seal test. With ``lip_seal``: every lip point over cap ``k``, their gaps to it spread
        by at most the lip's compliance (:meth:`lip_gaps`). Otherwise the one-contact rule: cup
        axis vs. cap normal at the contact, and the contact on the cap top."""
        w, p = self.world, self.params
        d = w.data
        if p.lip_seal:
            gaps = self.lip_gaps(k)
            return bool(np.isfinite(gaps).all() and gaps.max() - gaps.min() <= p.lip_compliance)
        z = d.site_xmat[w.tool_site].reshape(3, 3)[:, 2]
        cos = float(z @ normal_cup_to_cap)
        if cos < np.cos(np.deg2rad(p.seal_angle_deg)):
            return False
        b = w.body_ids[k]
        axis = d.xmat[b].reshape(3, 3)[:, 2]
        rel = point - d.xpos[b]
        radial = np.linalg.norm(rel - (rel @ axis) * axis)
        return bool(radial <= p.seal_region * w.cap_radius[k])

    def lip_gaps(self, k: int) -> np.ndarray:
        """The distance (m) along the cup axis from each lip point (``lip_points`` on a circle of
        ``cup_radius`` in the cup face) to mushroom ``k``'s cap; ``inf`` where the point's ray
        meets air, soil, another mushroom or the cap's stem first, or meets it further than the
        lip could reach (its compliance plus the setback)."""
        w = self.world
        m, d = w.model, w.data
        frame = d.site_xmat[w.tool_site].reshape(3, 3)
        axis = frame[:, 2].copy()  # out of the cup, towards the cap
        reach = LIP_RAY_SETBACK + self.params.lip_compliance
        gaps = np.full(len(self._lip_offsets), np.inf)
        for i, (u, v) in enumerate(self._lip_offsets):
            origin = d.site_xpos[w.tool_site] + u * frame[:, 0] + v * frame[:, 1] - LIP_RAY_SETBACK * axis
            dist = mujoco.mj_ray(m, d, origin, axis, None, 1, w.cup_body, self._ray_geom)
            g = int(self._ray_geom[0])
            if 0 <= dist <= reach and g >= 0 and w.is_cap[g] and w.geom_mushroom[g] == k:
                gaps[i] = dist - LIP_RAY_SETBACK
        return gaps

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
        ep.seal_step, ep.seal_tool_x = ep.steps, d.site_xmat[w.tool_site, 0::3].copy()
        self._seal_time = float(d.time)
        if k == ep.target:
            ep.ever_gripped_target = True

    def release(self) -> None:
        w, ep = self.world, self.state
        w.data.eq_active[w.grip_eq[ep.grip]] = 0
        w.model.geom_contype[w.cup_geom], w.model.geom_conaffinity[w.cup_geom] = w.cup_mask
        ep.grip, ep.grip_util, ep.seal_step, ep.seal_tool_x = -1, 0.0, -1, None

    def update_hold(self) -> None:
        pass  # the seal forms in ``on_contact``

    # ------------------------------------------------------------------ grip loss
    def grip_wrench(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Load the seal carries: world force the cup exerts on the gripped mushroom, its moment
        about the cup contact point (the tool site on the cup face), and the cup axis."""
        w, k = self.world, self.state.grip
        d = w.data
        nefc = d.nefc
        rows = (d.efc_type[:nefc] == _EQ) & (d.efc_id[:nefc] == w.grip_eq[k])  # eq ids only
        q = ph.wrench_from_rows(w.model, d, rows, self._qfrc)
        b = w.body_ids[k]
        force, torque = ph.free_body_wrench(q, w.dofadr[k], d.xmat[b].reshape(3, 3))
        moment = ph.moment_about(force, torque, d.xpos[b], d.site_xpos[w.tool_site])
        return force, moment, d.site_xmat[w.tool_site].reshape(3, 3)[:, 2].copy()

    def check_hold(self) -> None:
        """The seal lets go when its load reaches its capacity (the detached target's grip is
        then lost)."""
        ep = self.state
        k = ep.grip
        if k < 0:
            return
        force, torque_c, z = self.grip_wrench()
        fz, shear = ph.axial_split(force, z)
        tz, bend = ph.axial_split(torque_c, z)
        p = self.params
        # The vacuum rises over the evacuation time once the lip seals.
        rise = (1.0 - math.exp(-(self.world.data.time - self._seal_time) / p.evacuation_time)
                if p.lip_seal and p.evacuation_time > 0 else 1.0)
        load = ph.grip_utilisation(max(0.0, -fz), shear, bend, abs(tz), p, compression=max(0.0, fz),
                                   vacuum_fraction=rise)
        ep.grip_util += self._load_blend * (load - ep.grip_util)
        if ep.grip_util >= 1.0:
            if k == ep.target:  # lost with the target off its roots, or before they gave way
                ep.grip_lost = ep.grip_lost or ep.target_detached
                ep.seal_overloaded = ep.seal_overloaded or not ep.target_detached
            self.release()

    # ------------------------------------------------------------------ episode
    def after_step(self) -> None:
        pass

    def dead_end(self) -> bool:
        """The target is off its roots and not held, or a latched seal holds another mushroom."""
        ep = self.state
        knocked_off = ep.target_detached and ep.grip != ep.target
        wrong_seal = self.latched and ep.grip >= 0 and ep.grip != ep.target
        return knocked_off or wrong_seal

    def observation(self) -> tuple[float, float, float]:
        """(suction on, sealed, seal load / capacity)."""
        ep = self.state
        return float(ep.tool_on), float(ep.grip >= 0), ep.grip_util
