"""Mushroom placement: the SMS3D paper's Algorithm 1 with a real mesh-intersection overlap test.

For each requested mushroom, up to ``max_attempts`` times: pick a model, sample a position,
roll/pitch ~ N(0, sigma^2), yaw ~ U[0, 2 pi), ``R = Rz Ry Rx``, uniform scale and per-axis
stretch; set the stem base on the soil; reject when the intersection-over-union with one of the
``neighbours`` nearest placed mushrooms whose bounding spheres touch it exceeds ``overlap_iou``
(of their meshes, the paper's test, or with ``overlap_solids="hulls"`` of the convex hulls of cap
and stem that MuJoCo collides).
Intersection volumes are exact mesh booleans (manifold3d), spared where certain bounds already
decide (``generator.overlap``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from generator.config import PlacementConfig, Species
from generator.geometry import OrientedBox, rotation_xyz
from generator.mushroom_models import MushroomModel, model_library, mushroom_mass
from generator.overlap import OverlapCounts, Posed, exceeds_iou, model_solid
from generator.scene import MushroomInstance
from generator.terrain import Terrain


@dataclass(frozen=True)
class PlacementStats:
    """How placement went: ``placed`` of ``requested`` after ``attempts`` tries in total, with
    ``mesh_tests`` exact booleans and ``bound_tests`` proxy booleans."""

    requested: int
    placed: int
    attempts: int
    mesh_tests: int
    bound_tests: int = 0


def make_instance(
    index: int, model: MushroomModel, stem_base: np.ndarray, rotation: np.ndarray,
    scale: float, stretch: np.ndarray, insertion_depth: float,
) -> MushroomInstance:
    """Pose a model: stem base on the soil, sunk ``insertion_depth`` along its stem axis."""
    scale_vector = scale * stretch
    axis = rotation[:, 2]
    position = stem_base - insertion_depth * axis
    cap_centre, cap_size = model.cap_box
    obb = OrientedBox(rotation @ (scale_vector * cap_centre) + position, cap_size * scale_vector, rotation.copy())
    cap_top = position + rotation @ (scale_vector * np.array([0.0, 0.0, model.cap_top_z]))
    diameter = model.cap_diameter * scale * float(np.mean(stretch[:2]))
    return MushroomInstance(
        id=index, species=model.species, model_id=model.model_id, position=position,
        rotation=rotation, scale=float(scale), stretch=stretch, stem_base=stem_base,
        cap_top=cap_top, cap_obb=obb, cap_diameter=diameter, mass=mushroom_mass(model.species, diameter),
    )


def sample_tilt(config: PlacementConfig, rng: np.random.Generator, size: int = 2) -> np.ndarray:
    """Roll and pitch in radians: N(0, sigma^2), or its absolute value (``half_normal``)."""
    angles = rng.normal(0.0, np.deg2rad(config.tilt_std_deg), size=size)
    return np.abs(angles) if config.tilt_distribution == "half_normal" else angles


def place_mushrooms(
    config: PlacementConfig, terrain: Terrain, rng: np.random.Generator
) -> tuple[list[MushroomInstance], PlacementStats]:
    """Run Algorithm 1; always terminates after at most ``num_mushrooms * max_attempts`` tries."""
    species_pool: tuple[Species, ...] = ("white", "brown") if config.species == "mixed" else (config.species,)
    placed: list[tuple[MushroomInstance, Posed]] = []
    centres = np.empty((config.num_mushrooms, 3))
    radii = np.empty(config.num_mushrooms)
    attempts = 0
    counts = OverlapCounts()
    for _ in range(config.num_mushrooms):
        for _attempt in range(config.max_attempts):
            attempts += 1
            species = species_pool[int(rng.integers(len(species_pool)))]
            model_id = int(rng.integers(len(model_library(species))))
            x = rng.uniform(*config.x_range)
            y = rng.uniform(*config.y_range)
            roll, pitch = sample_tilt(config, rng)
            yaw = rng.uniform(0.0, 2 * np.pi)
            rotation = rotation_xyz(roll, pitch, yaw)
            scale = rng.uniform(*config.scale_range)
            stretch = rng.uniform(*config.stretch_range, size=3)
            stem_base = np.array([x, y, terrain.height_at(x, y)])
            model = model_library(species)[model_id]
            candidate = make_instance(len(placed), model, stem_base, rotation, scale, stretch, config.insertion_depth)
            posed = Posed.place(model_solid(species, model_id), candidate.transform, candidate.scale_vector)

            # Bounding spheres that touch: a vectorised pass with a little slack, then the scalar
            # test on the few left, so exactly the same neighbours are chosen as one by one.
            n = len(placed)
            gaps = np.sqrt(((centres[:n] - posed.centre) ** 2).sum(axis=1))
            near = np.flatnonzero(gaps < (radii[:n] + posed.radius) * (1 + 1e-9))
            touching = [placed[i] for i in near
                        if np.linalg.norm(placed[i][1].centre - posed.centre) < placed[i][1].radius + posed.radius]
            touching.sort(key=lambda p: float(np.linalg.norm(p[0].stem_base - stem_base)))
            # The hull test is the physics' (every touching neighbour); the paper's, the k nearest.
            kept = touching if config.overlap_solids == "hulls" else touching[: config.neighbours]
            neighbours = [p[1] for p in kept]
            if not exceeds_iou(posed, neighbours, config.overlap_iou, counts, config.overlap_solids):
                centres[n], radii[n] = posed.centre, posed.radius
                placed.append((candidate, posed))
                break
    stats = PlacementStats(config.num_mushrooms, len(placed), attempts, counts.exact, counts.bounds)
    return [p[0] for p in placed], stats
