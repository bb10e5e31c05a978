"""Target selection and reachability.

Rules (``TargetRule``, the env's ``target`` argument): drawn uniformly within a class of the
study (:data:`CLASS_RULES`): ``"harvest_ready"`` (the default: a cap at or above the harvest
size, what a farm picks now), ``"isolated"``, ``"crowded"``, ``"approach_blocked"`` (harvest-ready
ones by their neighbours) and ``"small"`` (below the harvest size); or ``"tallest"`` (highest cap
top among reachable mushrooms, v1's default: the cup meets it before any neighbour),
``"largest"`` (cap diameter), ``"index"`` (``TargetRule.index``), ``"random"``.
Reachability: inverse kinematics (bounded least squares on the arm-only model) reaches a
pre-grasp pose above the cap top along the stem axis and the grasp pose itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from scipy.optimize import least_squares

from sms3d_env.records import check_choice, check_int, check_number

#: Rules that draw the target uniformly among the mushrooms of one class (``target_classes``).
CLASS_RULES = ("harvest_ready", "isolated", "crowded", "approach_blocked", "small")
RULES = ("tallest", "largest", "index", "random", *CLASS_RULES)
#: The rules a study can sweep: every rule but ``"index"``, which names one mushroom of one bed.
SWEPT_RULES = tuple(r for r in RULES if r != "index")
#: Farms harvest Agaricus at caps of about 50-60 mm (docs/physics.md, harvest size): the
#: smallest cap picked now (m).
HARVEST_DIAMETER = 0.050
#: A harvest-ready cap is isolated when every neighbouring cap's edge is at least this far from
#: its edge (m, horizontally), crowded when one is closer than ``CROWDED_GAP``. ASSUMPTION: a
#: cup's radius of free space (10 mm) around the cap, and caps that touch.
ISOLATED_GAP, CROWDED_GAP = 0.010, 0.002
#: The approach is blocked when a neighbour's cap reaches into the cylinder the cup sweeps on its
#: way down the stem axis: this radius (m; the 10 mm cup and its 5 mm tube-and-bellows margin,
#: ASSUMPTION) over ``APPROACH_HEIGHT`` above the cap top (the pre-grasp stand-off).
APPROACH_RADIUS, APPROACH_HEIGHT = 0.015, 0.05


@dataclass(frozen=True)
class TargetRule:
    """Which mushroom of the bed an episode picks (the env's ``target`` argument; a rule name
    alone is ``TargetRule(rule)``; ``reset(options={"target": i})`` picks mushroom ``i`` for one
    reset).

    Attributes:
        rule: a class of :data:`CLASS_RULES` (``"harvest_ready"``, the default: uniform among
            the reachable caps of at least ``harvest_diameter``), ``"tallest"`` (v1's),
            ``"largest"``, ``"random"`` (each among the reachable mushrooms tilted no more than
            ``max_tilt_deg``), or ``"index"``.
        index: the mushroom ``rule="index"`` picks (an index into the scene's instances);
            refused with another rule, which would ignore it.
        max_tilt_deg: mushrooms whose stem axis is tilted more than this from vertical (deg)
            are not chosen by the other rules.
        harvest_diameter: the smallest cap a farm picks now (m): the class rules' harvest size.
    """

    rule: str = "harvest_ready"
    index: int = 0
    max_tilt_deg: float = 45.0
    harvest_diameter: float = HARVEST_DIAMETER

    def __post_init__(self) -> None:
        check_choice("TargetRule.rule", self.rule, RULES)
        check_int("TargetRule.index", self.index)
        if self.index and self.rule != "index":
            raise ValueError(f"TargetRule.index picks a mushroom for rule='index'; with rule={self.rule!r} it "
                             f"would be ignored (got index={self.index!r})")
        check_number("TargetRule.max_tilt_deg", self.max_tilt_deg, 0.0, 90.0, "a finite number in [0, 90] (deg)")
        check_number("TargetRule.harvest_diameter", self.harvest_diameter, 0.0, 0.2, "a cap diameter in [0, 0.2] m")


class Reachability:
    """IK feasibility on the arm-only model (a few ms per query; a repeated query is answered from
    a cache of the ``cache_size`` most recently used solves: a bed pool asks the same ones at each
    of its beds' resets).

    A solve starts at home. Where it fails from there, it is tried again from home with one
    revolute joint turned by each of ``RESTART_TURNS`` (where the joint's range allows); each
    unlimited joint of a solution is taken within half a turn of home, and the solution kept is
    the one whose straight joint-space path from home stays best conditioned (the largest least
    :meth:`conditioning` along it: the path the scripted picker's joint-space transfer follows).
    Measured why: from the hanging Jaco's tool-down home, the least squares stalled at the wrist
    singularity (joint 4 near 0, joint 5 near pi, where the residual's gradient vanishes) for 3 of
    1,600 estimated pre-grasp poses (400 held-out beds at each of 0 / 10 / 20 / 30 deg); the
    restarts solve all three. Kept by the end's conditioning alone, one of them was reached by a
    path that turned joints 5 and 6 by 3.7 and 4.6 rad and stalled 6 mm short."""

    cache_size = 8192
    RESTART_TURNS = (np.pi / 2, -np.pi / 2, np.pi)

    def __init__(self, model: mujoco.MjModel, site: str, arm_qadr: np.ndarray, home: np.ndarray) -> None:
        self.model, self.data = model, mujoco.MjData(model)
        self.site = model.site(site).id
        self.qadr = arm_qadr
        jids = [int(model.dof_jntid[i]) for i in range(model.nv)]
        lo = np.full(len(arm_qadr), -2 * np.pi)
        hi = np.full(len(arm_qadr), 2 * np.pi)
        for k, a in enumerate(arm_qadr):
            j = jids[a]
            if model.jnt_limited[j]:
                lo[k], hi[k] = model.jnt_range[j] + np.array([1e-3, -1e-3])
        self.lo, self.hi, self.home = lo, hi, np.clip(home, lo + 1e-6, hi - 1e-6)
        hinge = np.array([model.jnt_type[jids[a]] == mujoco.mjtJoint.mjJNT_HINGE for a in arm_qadr])
        self.revolute = np.flatnonzero(hinge)
        self.unlimited = hinge & ~model.jnt_limited[[jids[a] for a in arm_qadr]].astype(bool)
        self.dofs = np.asarray(arm_qadr)  # an arm-only model: each joint's qpos address is its dof's
        self._solved: dict[tuple[bytes, bytes, tuple[float, ...]], np.ndarray | None] = {}

    def _res(self, q: np.ndarray, pos: np.ndarray, z: np.ndarray) -> np.ndarray:
        self.data.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        r = self.data.site_xmat[self.site].reshape(3, 3)
        return np.r_[(self.data.site_xpos[self.site] - pos) * 10, r[:, 2] - z]

    def solve(self, cap_top: np.ndarray, axis: np.ndarray, offsets: tuple[float, ...] = (0.05, 0.0)
              ) -> np.ndarray | None:
        """Joint angles with the cup on the stem axis ``offsets[-1]`` above the cap top, facing
        down the axis, solved from home through the earlier offsets; None if one fails. The solve
        is deterministic, so a cached answer is the answer."""
        cap_top, axis = np.asarray(cap_top, np.float64), np.asarray(axis, np.float64)
        key = (cap_top.tobytes(), axis.tobytes(), tuple(float(o) for o in offsets))
        if key in self._solved:
            q = self._solved.pop(key)  # re-inserted below as the most recently used
        else:
            q = self._solve(cap_top, axis, offsets)
            if len(self._solved) >= self.cache_size:
                del self._solved[next(iter(self._solved))]  # the least recently used
        self._solved[key] = q
        return None if q is None else q.copy()

    def _solve(self, cap_top: np.ndarray, axis: np.ndarray, offsets: tuple[float, ...]) -> np.ndarray | None:
        z = -axis / np.linalg.norm(axis)
        q = self._solve_from(self.home, cap_top, z, offsets)
        if q is not None:
            return q
        solutions = []
        for k in self.revolute:
            for turn in self.RESTART_TURNS:
                start = self.home.copy()
                start[k] += turn
                if self.lo[k] < start[k] < self.hi[k]:
                    q = self._solve_from(start, cap_top, z, offsets)
                    if q is not None:
                        solutions.append(self._near_home(q))
        return max(solutions, key=self.path_conditioning) if solutions else None

    def _near_home(self, q: np.ndarray) -> np.ndarray:
        """``q`` with each unlimited joint turned by whole turns to within half a turn of home
        (the same arm pose), where that stays within the solve's bounds."""
        near = self.home + (q - self.home + np.pi) % (2 * np.pi) - np.pi
        return np.where(self.unlimited & (self.lo <= near) & (near <= self.hi), near, q)

    def path_conditioning(self, q: np.ndarray, samples: int = 21) -> float:
        """The least :meth:`conditioning` on the straight joint-space path from home to ``q``."""
        return min(self.conditioning(self.home + s * (q - self.home)) for s in np.linspace(0.0, 1.0, samples))

    def _solve_from(self, q: np.ndarray, cap_top: np.ndarray, z: np.ndarray, offsets: tuple[float, ...]
                    ) -> np.ndarray | None:
        """The cup ``offsets[-1]`` before ``cap_top`` along the tool axis ``z``, solved from ``q``
        through the earlier offsets; None if one fails."""
        for offset in offsets:
            sol = least_squares(self._res, q, bounds=(self.lo, self.hi), max_nfev=100,
                                args=(cap_top - z * offset, z))
            if sol.cost > 1e-6:
                return None
            q = np.clip(sol.x, self.lo + 1e-6, self.hi - 1e-6)
        return q

    def conditioning(self, q: np.ndarray) -> float:
        """The smallest singular value of the tool site's Jacobian (m or rad per rad or m) over
        the arm's joints at ``q``: 0 at a singular configuration."""
        self.data.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)
        jac = np.zeros((6, self.model.nv))
        mujoco.mj_jacSite(self.model, self.data, jac[:3], jac[3:], self.site)
        return float(np.linalg.svd(jac[:, self.dofs], compute_uv=False)[-1])

    def reachable(self, cap_top: np.ndarray, axis: np.ndarray, standoff: float = 0.05) -> bool:
        return self.solve(cap_top, axis, (standoff, 0.0)) is not None


def cap_gaps(insts: Any) -> np.ndarray:
    """Each mushroom's horizontal gap from its cap's edge to the nearest neighbouring cap's edge
    (m; negative where the caps' outlines overlap seen from above; inf alone)."""
    tops = np.array([inst.cap_top[:2] for inst in insts], float).reshape(-1, 2)
    radii = np.array([inst.cap_diameter / 2 for inst in insts], float)
    gaps = np.linalg.norm(tops[:, None] - tops[None], axis=2) - radii[:, None] - radii[None]
    np.fill_diagonal(gaps, np.inf)
    return gaps.min(axis=1) if len(insts) > 1 else np.full(len(insts), np.inf)


def approach_blocked(insts: Any) -> np.ndarray:
    """Whether a neighbour's cap reaches into the cylinder (``APPROACH_RADIUS``) the cup sweeps
    down each mushroom's stem axis from ``APPROACH_HEIGHT`` above its cap top: a neighbour whose
    cap top stands above the target's cap top along that axis, its cap's edge within the
    cylinder's radius of the axis."""
    tops = np.array([inst.cap_top for inst in insts], float).reshape(-1, 3)
    axes = np.array([np.asarray(inst.rotation)[:, 2] for inst in insts], float).reshape(-1, 3)
    radii = np.array([inst.cap_diameter / 2 for inst in insts], float)
    rel = tops[None] - tops[:, None]  # [i, j]: neighbour j's cap top from mushroom i's
    along = np.einsum("ijk,ik->ij", rel, axes)
    lateral = np.linalg.norm(rel - along[..., None] * axes[:, None], axis=2)
    reaches = (along > 0.0) & (along < APPROACH_HEIGHT) & (lateral - radii[None] < APPROACH_RADIUS)
    np.fill_diagonal(reaches, False)
    return reaches.any(axis=1)


def target_classes(insts: Any, harvest_diameter: float = HARVEST_DIAMETER) -> dict[str, np.ndarray]:
    """Each class of :data:`CLASS_RULES` as a boolean mask over the bed's mushrooms: harvest-ready
    (cap >= ``harvest_diameter``), and among those isolated, crowded, approach-blocked; small (the
    rest)."""
    ready = np.array([inst.cap_diameter >= harvest_diameter for inst in insts], bool)
    gaps = cap_gaps(insts)
    return {"harvest_ready": ready, "isolated": ready & (gaps >= ISOLATED_GAP),
            "crowded": ready & (gaps < CROWDED_GAP), "approach_blocked": ready & approach_blocked(insts),
            "small": ~ready}


def select_target(scene: Any, rule: str, rng: np.random.Generator, reach: Reachability,
                  index: int = 0, max_tilt_deg: float = 45.0,
                  harvest_diameter: float = HARVEST_DIAMETER) -> tuple[int, bool]:
    """Returns (instance id, reachable). A class rule with no reachable member in the bed falls
    back to its first member (unreachable), or, for a bed without the class, to a uniform draw
    over the bed."""
    if rule not in RULES:
        raise ValueError(f"target rule must be one of {RULES}, got {rule!r}")
    insts = scene.instances
    n = len(insts)
    if rule == "index":
        if not 0 <= index < n:
            raise ValueError(f"target index {index} out of range for {n} mushrooms")
        i = int(index)
        return i, _ok(insts[i], reach, max_tilt_deg)
    if rule in CLASS_RULES:
        members = np.flatnonzero(target_classes(insts, harvest_diameter)[rule])
        order = list(rng.permutation(members)) if len(members) else list(rng.permutation(n))
    elif rule == "random":
        order = list(rng.permutation(n))
    elif rule == "tallest":
        order = list(np.argsort([-inst.cap_top[2] for inst in insts], kind="stable"))
    else:
        order = list(np.argsort([-inst.cap_diameter for inst in insts], kind="stable"))
    for i in order:
        if _ok(insts[int(i)], reach, max_tilt_deg):
            return int(i), True
    return int(order[0]), False


def pickable(cap_top: np.ndarray, axis: np.ndarray, reach: Reachability, max_tilt_deg: float) -> bool:
    """Whether a mushroom whose cap top and unit stem axis are these is a target: it leans at
    most ``max_tilt_deg`` from vertical and the IK reaches it (``Reachability.reachable``)."""
    if np.degrees(np.arccos(np.clip(axis[2], -1, 1))) > max_tilt_deg:
        return False
    return reach.reachable(np.asarray(cap_top), axis)


def _ok(inst: Any, reach: Reachability, max_tilt_deg: float) -> bool:
    return pickable(inst.cap_top, np.asarray(inst.rotation)[:, 2], reach, max_tilt_deg)
