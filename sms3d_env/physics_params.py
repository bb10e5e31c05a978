"""The picking model's parameters (``PickPhysicsParams``), apart from the MuJoCo code that uses them.

They live here, not in :mod:`sms3d_env.physics` (which imports them from this module), so that the
``sms3d sweep`` parser can name its physics variants without importing MuJoCo.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sms3d_env.records import record_of


@dataclass(frozen=True)
class PickPhysicsParams:
    """Parameters of the picking model.

    Attributes:
        pull_force: axial tension at the root that detaches a mushroom (N). ASSUMPTION (no source
            for a pull-off force): 8 N, 2.5x the 3.2 N of shear Xu et al. 2025 measured to grip
            and twist, as pickers are told to twist, not pull; the study sweeps it.
        bend_moment: bending moment at the root that detaches (N m). ASSUMPTION (no source):
            about 2 N of side force on a cap 4 cm above the root, 8x what gravity gives a 50 g
            mushroom tilted by 30 degrees. (0.02 N m, an earlier value, is 0.5 N at the cap: a
            cup's approach alone uprooted mushrooms.) The study sweeps it x1/4-x16: the
            scripted picker's success does not move with it.
        twist_torque: torque about the stem that detaches (N m). Xu et al. 2025: more than 3.2 N
            of shear grips and twists a mushroom, 0.02-0.1 N m at a grip radius of 7-30 mm;
            0.03 N m, the lower part of that range, is an ASSUMPTION within it (v1: 0.006, a
            fifth of the range's bottom). Twisting detaches most easily ("twist, do not pull").
        vacuum: suction vacuum (Pa): 60 kPa, the relative vacuum at which suction cups' holding
            forces are stated (Schmalz); ASSUMPTION for a harvester (none publishes its vacuum;
            Penn State's cup adjusts it). v1: 20 kPa.
        cup_radius: cup radius (m), 10 mm (a 20 mm cup) as in docs/physics.md.
        seal_angle_deg: largest angle between the cup axis and the cap surface normal at the
            contact that still seals. ASSUMPTION: a 10 mm cup tilted 20 degrees lifts one rim edge
            by 2a sin(20) = 6.8 mm (docs/physics.md, derived), about a bellows stroke.
        seal_region: the contact must lie within this fraction of the cap radius from the stem
            axis (the cap top, not its softer, curved rim). ASSUMPTION.
        seal_force: cup-on-cap normal force needed to form a seal (N). ASSUMPTION.
        shear_friction: shear capacity of the seal as a fraction of its normal force (the
            holding force, plus the cup's pressing force with ``seal_preload``): 0.3, the top of
            Schmalz's reference friction coefficient for suction cups on wet surfaces (0.2-0.3;
            a cap is moist). v1: 0.5 (ASSUMPTION, rubber on a moist cap).
        bruise_force: cap contact normal force that bruises (N). ASSUMPTION: docs/physics.md
            reports no numeric bruising threshold.
        disturb_tolerance: a neighbour moved further than this (m) counts as disturbed. ASSUMPTION.
        lift_height: height the target must be lifted above its starting cap top (m). ASSUMPTION.
        settle_time: simulated seconds after reset before detachment is checked (the soft welds
            take up gravity).
        seal_response_time: time constant (s) of the seal's load as the grip-loss rule reads it
            (a first-order low-pass of the load per physics step; 0 reads each step's load).
            ASSUMPTION (no published peel time for a suction cup): a seal peels when its lip
            lifts and air flows in, which takes milliseconds, not the one physics step of an
            impulse; 20 ms is the order of a vacuum cup's pressure response. Read per physics
            step, the load peaked for one step when a mushroom's root let go, and the Jaco's
            success at 20-30 degrees depended on the step size (1 ms: 399/386 of 400, 2 ms:
            390/375, 4 ms: 386/358); with this and ``seal_preload``, 400/399, 400/400, 399/400.
        seal_preload: the cup's pressing force on the cap adds to the normal force behind the
            seal's shear, bending and twist capacities (statics of a lip pressed on a surface;
            Dex-Net 3.0's suction contact model, Mahler et al. 2018, bounds friction and torsion
            by the normal force, vacuum included). False: the capacities of the holding force
            alone (the removed v0).
        lip_seal: judge the seal on the cup's whole lip (Dex-Net 3.0's perimeter model): it
            forms only when every one of ``lip_points`` points of the lip (radius
            ``cup_radius``) lies over the target's cap, the spread of their distances to it
            along the cup axis within ``lip_compliance``; a lip point over air, soil, a
            neighbour or past the cap's edge leaks. It replaces the one-contact rule
            (``seal_angle_deg``, ``seal_region``). False: the one-contact rule (v1).
        lip_compliance: the rim-height mismatch the cup's lip or bellows absorbs (m), the stroke
            ``S`` of a bellows cup. ASSUMPTION: bellows suction cups "compensate for variations
            in height" (Piab, SMC ZPT catalogue) but no stored datasheet gives the stroke of a
            20 mm bellows; 5 mm is the order of a 1.5-fold bellows of that size. A rigid lip
            tilted by theta on a plane spreads by about 2a tan(theta), so the lip rule tolerates
            about atan(S / 2a).
        lip_points: points on the lip the seal test checks (evenly spaced).
        evacuation_time: time constant (s) of the vacuum's rise once the lip seals: the holding
            force is ``holding_force (1 - exp(-t / evacuation_time))`` t seconds after sealing
            (with ``lip_seal``). ASSUMPTION: no source for a small cup's evacuation time (hose
            and ejector dependent); 50 ms, a short hose on a venturi ejector.
        slip_bruising: a cap also bruises by slip-shear, the documented mechanism (Burton 2004:
            slip-shear of the surface hyphae, then browning): when the friction work done on it
            by contacts slipping over its surface (a cup sliding before it seals, a lifted cap
            scraping a neighbour) reaches ``slip_bruise_work``. False: bruising by pressure
            alone (``bruise_force``; v1).
        slip_bruise_work: friction work (J) slipping on one cap that bruises it. ASSUMPTION: no
            numeric slip-shear threshold is published (Burton's bruisometer measures it, values
            not stored); 5 mJ is 1 N of friction dragged 5 mm across the cap.
        mushrooms_collide: every mushroom collides with every other, rooted or loose, so a lifted
            cap pushes, drags or scrapes its neighbours. The bed's collision hulls must not
            interpenetrate at rest (more than 1 mm): generated beds need
            ``placement.overlap_iou = 0``; a bed that does is refused at reset. False: mushrooms
            touch only the robot and the soil (v1).
        compliant_root: the root bends and twists before it lets go (:mod:`sms3d_env.roots`): a
            ball constraint at the stem base, rotational springs that reach ``bend_moment`` after
            ``bend_angle_deg`` of bending and ``twist_torque`` after ``twist_angle_deg`` of twist,
            and the same failure rule (``physics.root_utilisation``). False: a stiff weld that
            lets go at those loads after a fraction of a degree (v1).
        bend_angle_deg: bending of the stem at its base (deg) when the bending moment reaches
            ``bend_moment`` (with ``compliant_root``). ASSUMPTION (no published bend angle at
            detachment): 15 degrees, the "bend into free space" of the Silsoe picker before its
            twist, short of the 30-45 degrees after which a stem snaps.
        twist_angle_deg: twist of the stem (deg) when the torque reaches ``twist_torque`` (with
            ``compliant_root``). ASSUMPTION (no published twist angle at detachment): 30 degrees,
            a wrist's "gentle twist" of a twelfth of a turn.
        root_damping_ratio: damping of the root springs as a fraction of critical (each
            mushroom's own inertia about its stem base). ASSUMPTION: 0.5, plant tissue that does
            not ring after a push.
        stem_in_casing: a released mushroom meets the casing from the moment it lets go: its
            stem rests on the floor of its hole (``world.add_stem_sockets``) and its cap meets the
            soil (one that tips over lands on it), whatever the tool; the stem meets the soil
            once it has risen ``physics.SOIL_CLEARANCE`` out of it. False: a released mushroom
            touches no soil until it has risen 5 mm, so one let go before falls through the
            casing (the hand's stems rest on the floor) (v1). KNOWN SIMPLIFICATION: the hole has
            no wall, so the released stem is not held sideways until it has risen out.
        clean_pick: success needs a clean pick, as a grower judges it: besides the target picked
            unbruised, no neighbour moved further than ``disturb_tolerance`` or knocked off its
            roots (``info["neighbours_disturbed"]``; ``info["target_picked"]`` says whether the
            target itself was picked). False: neighbours do not count (v1).
    """

    pull_force: float = 8.0
    bend_moment: float = 0.08
    twist_torque: float = 0.03
    vacuum: float = 60e3
    cup_radius: float = 0.010
    seal_angle_deg: float = 20.0
    seal_region: float = 0.5
    seal_force: float = 0.3
    shear_friction: float = 0.3
    bruise_force: float = 25.0
    disturb_tolerance: float = 0.005
    lift_height: float = 0.03
    settle_time: float = 0.1
    seal_response_time: float = 0.02
    seal_preload: bool = True
    lip_seal: bool = True
    lip_compliance: float = 0.005
    lip_points: int = 16
    evacuation_time: float = 0.05
    clean_pick: bool = True
    compliant_root: bool = True
    bend_angle_deg: float = 15.0
    twist_angle_deg: float = 30.0
    root_damping_ratio: float = 0.5
    mushrooms_collide: bool = True
    slip_bruising: bool = True
    slip_bruise_work: float = 0.005
    stem_in_casing: bool = True

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"PickPhysicsParams.{name} must be a finite number >= 0, got {value!r}")
        if not 0 < self.seal_angle_deg < 90:
            raise ValueError("PickPhysicsParams.seal_angle_deg must be in (0, 90)")
        for name in ("bend_angle_deg", "twist_angle_deg"):
            if not 0 < getattr(self, name) < 180:
                raise ValueError(f"PickPhysicsParams.{name} must be in (0, 180) degrees, got {getattr(self, name)!r}")
        if self.lip_points < 3 or self.lip_points != int(self.lip_points):
            raise ValueError(f"PickPhysicsParams.lip_points must be an integer >= 3, got {self.lip_points!r}")

    @property
    def holding_force(self) -> float:
        """Suction holding force = vacuum x cup area (N); 18.8 N with the defaults (v1: 6.3 N)."""
        return self.vacuum * math.pi * self.cup_radius**2


#: ``SMS3DPick-v1``'s picking model (its registration's ``physics``): the one-contact seal, a stiff
#: weld for a root, mushrooms that pass through each other, pressure bruising only, neighbours
#: that do not count, a 20 kPa vacuum, friction 0.5, a 0.006 N m twist-off torque.
V1_PHYSICS = {"vacuum": 20e3, "shear_friction": 0.5, "twist_torque": 0.006, "lip_seal": False,
              "clean_pick": False, "mushrooms_collide": False, "slip_bruising": False, "compliant_root": False,
              "stem_in_casing": False}


def physics_for(physics: PickPhysicsParams | Mapping[str, Any] | None, cup_radius: float) -> PickPhysicsParams:
    """The env's ``physics`` argument as a record: a record as given; its mapping form (field
    name -> value; a key that is no field is refused by name) or None with the defaults for the
    rest, the cup radius the robot's unless given."""
    if isinstance(physics, PickPhysicsParams):
        return physics
    if physics is None:
        return PickPhysicsParams(cup_radius=cup_radius)
    if not isinstance(physics, Mapping):
        raise TypeError(f"physics must be a PickPhysicsParams, its mapping form or None, got "
                        f"{type(physics).__name__} {physics!r}")
    return record_of(PickPhysicsParams, {"cup_radius": cup_radius, **physics}, "physics")
