"""The scan: the bed as it stands now, what a look at it detects, the candidates a harvester
would pick and the features it knows them by.

A scan reads the *current* bed: ``current_scene`` moves each mushroom of the generated scene to
where the physics has it now (so a knocked or moved mushroom is seen where it lies) and leaves
out the collected ones; the pose source then estimates every mushroom still in view (its cap top
above the soil) as it would at a pick env's reset. A detection keeps the true mushroom id for
scoring only; the observation holds estimates alone.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from sms3d_env.targets import approach_blocked, cap_gaps

#: Entries of each candidate's row in the observation, in order.
CANDIDATE_FEATURES = (
    "available",  # 1: a candidate of the last scan not collected since; 0: an empty slot
    "cap_top_x", "cap_top_y", "cap_top_z",  # estimated cap top (m, world)
    "axis_x", "axis_y", "axis_z",  # estimated stem axis (unit)
    "cap_diameter",  # estimated cap diameter (m)
    "nearest_gap",  # horizontal gap from its cap's edge to the nearest detected cap's edge (m; 0.1 alone)
    "close_neighbours",  # other detected cap tops within CROWD_RADIUS of its own
    "approach_blocked",  # 1: a detected cap reaches into the cylinder the cup sweeps (targets.approach_blocked)
    "tool_distance",  # horizontal distance from the tool (m)
    "reachable",  # 1: the IK reaches its estimated pose and it leans at most max_tilt_deg
    "attempts",  # picks tried on it since the scan
)
#: Entries of the observation's bed-level vector, in order.
BED_FEATURES = ("time_s", "picked", "attempts", "scans", "failed_attempts", "candidates_available",
                "tool_x", "tool_y", "tool_z")
#: ``nearest_gap`` of a detection with no other detection in the bed (m).
NO_NEIGHBOUR_GAP = 0.1
#: ``close_neighbours`` counts the other cap tops within this horizontal distance (m): a feature's
#: scale, not physics (about one harvest-size cap diameter beyond the cap's own edge).
CROWD_RADIUS = 0.06


@dataclass(frozen=True)
class Detection:
    """One mushroom a scan saw: its estimated cap top (m), rotation (stem axis = column 2) and
    cap diameter (m); ``instance`` is the true mushroom, for scoring only."""

    instance: int
    cap_top: np.ndarray
    rotation: np.ndarray
    cap_diameter: float

    @property
    def axis(self) -> np.ndarray:
        return self.rotation[:, 2]


def current_scene(scene: Any, world: Any) -> Any:
    """``scene`` with every mushroom moved to its pose in ``world`` now: position and rotation
    from its body, the cap top from its site, the stem base and cap box moved with the body."""
    d = world.data
    insts = []
    for inst, b, site in zip(scene.instances, world.body_ids, world.cap_top_sites, strict=True):
        rot = d.xmat[b].reshape(3, 3).copy()
        pos = d.xpos[b].copy()
        turn = rot @ np.asarray(inst.rotation).T
        shift = pos - turn @ np.asarray(inst.position, float)  # a point of the mushroom: turn @ p + shift
        box = dataclasses.replace(inst.cap_obb, center=turn @ np.asarray(inst.cap_obb.center) + shift,
                                  rotation=turn @ np.asarray(inst.cap_obb.rotation))
        insts.append(dataclasses.replace(inst, position=pos, rotation=rot,
                                         stem_base=turn @ np.asarray(inst.stem_base) + shift,
                                         cap_top=d.site_xpos[site].copy(), cap_obb=box))
    return dataclasses.replace(scene, instances=tuple(insts) if isinstance(scene.instances, tuple) else insts)


def in_view(scene: Any, collected: set[int]) -> list[int]:
    """Mushrooms a look at the bed can see: not collected, their cap top above the soil."""
    terrain = scene.terrain
    return [i for i, inst in enumerate(scene.instances)
            if i not in collected and inst.cap_top[2] > float(terrain.height_at(inst.cap_top[0], inst.cap_top[1]))]


def detect(scene: Any, ids: list[int], pose_source: Any, rng: np.random.Generator) -> list[Detection]:
    """Each of ``ids`` estimated by ``pose_source`` on ``scene`` (in that order; the cap diameter
    the scene's: KNOWN SIMPLIFICATION, the oracle and noisy sources estimate no size)."""
    out = []
    for i in ids:
        est = pose_source(scene, i, rng)
        out.append(Detection(i, np.asarray(est.cap_top, float), np.asarray(est.rotation, float),
                             float(scene.instances[i].cap_diameter)))
    return out


def neighbour_features(detections: list[Detection]) -> np.ndarray:
    """(n, 3): each detection's ``nearest_gap`` (m; ``targets.cap_gaps``), ``close_neighbours``
    (other cap tops within ``CROWD_RADIUS``) and ``approach_blocked`` among the others, from the
    estimates alone."""
    if not detections:
        return np.zeros((0, 3))
    nearest = np.minimum(cap_gaps(detections), NO_NEIGHBOUR_GAP)
    tops = np.array([d.cap_top[:2] for d in detections], float)
    close = (np.linalg.norm(tops[:, None] - tops[None], axis=2) < CROWD_RADIUS).sum(axis=1) - 1
    blocked = approach_blocked(detections)
    return np.column_stack([nearest, close, blocked.astype(float)])


__all__ = ["BED_FEATURES", "CANDIDATE_FEATURES", "Detection", "current_scene", "detect", "in_view",
           "neighbour_features"]
