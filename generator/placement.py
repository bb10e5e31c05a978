"""Mushroom placement: the SMS3D paper's Algorithm 1 with a real mesh-intersection overlap test.

For each requested mushroom, up to ``max_attempts`` times: pick a model, sample a position,
roll/pitch ~ N(0, sigma^2), yaw ~ U[0, 2 pi), ``R = Rz Ry Rx``, uniform scale and per-axis
stretch; set the stem base on the soil; reject when the intersection-over-union with one of the
``neighbours`` nearest placed mushrooms whose bounding spheres touch it exceeds ``overlap_iou``.
Intersection volumes are exact mesh booleans (manifold3d).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import manifold3d
import numpy as np

from generator.config import PlacementConfig, Species
from generator.geometry import OrientedBox, rotation_xyz
from generator.mushroom_models import MushroomModel, model_library, mushroom_mass
from generator.scene import MushroomInstance
from generator.terrain import Terrain


@dataclass(frozen=True)
class _Solid:
    """A model as a manifold with its bounding sphere (model frame) and volume."""

    manifold: manifold3d.Manifold
    centre: np.ndarray
    radius: float
    volume: float


@cache
def _solid(species: Species, model_id: int) -> _Solid:
    mesh = model_library(species)[model_id].mesh
    solid = manifold3d.Manifold(manifold3d.Mesh(
        vert_properties=np.asarray(mesh.vertices, dtype=np.float32),
        tri_verts=np.asarray(mesh.faces, dtype=np.uint32),
    ))
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(mesh.vertices - centre, axis=1).max())
    return _Solid(solid, centre, radius, float(solid.volume()))


@dataclass
class _Placed:
    instance: MushroomInstance
    solid: manifold3d.Manifold  # transformed into the world
    centre: np.ndarray
    radius: float
    volume: float


@dataclass(frozen=True)
class PlacementStats:
    """How placement went: ``placed`` of ``requested`` after ``attempts`` tries in total."""

    requested: int
    placed: int
    attempts: int
    mesh_tests: int


def intersection_iou(a: manifold3d.Manifold, b: manifold3d.Manifold, volume_a: float, volume_b: float) -> float:
    """Volume IoU of two solids from an exact boolean intersection."""
    inter = (a ^ b).volume()
    union = volume_a + volume_b - inter
    return float(inter / union) if union > 0 else 0.0


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
    placed: list[_Placed] = []
    attempts = mesh_tests = 0
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

            solid = _solid(species, model_id)
            affine = candidate.transform
            centre = affine[:3, :3] @ solid.centre + affine[:3, 3]
            radius = solid.radius * float(candidate.scale_vector.max())
            touching = [p for p in placed if np.linalg.norm(p.centre - centre) < p.radius + radius]
            touching.sort(key=lambda p: float(np.linalg.norm(p.instance.stem_base - stem_base)))
            overlap = False
            world_solid = None
            if touching:
                world_solid = solid.manifold.transform(affine[:3].astype(np.float64))
                volume = solid.volume * float(np.prod(candidate.scale_vector))
                for other in touching[: config.neighbours]:
                    mesh_tests += 1
                    if intersection_iou(world_solid, other.solid, volume, other.volume) > config.overlap_iou:
                        overlap = True
                        break
            if not overlap:
                if world_solid is None:
                    world_solid = solid.manifold.transform(affine[:3].astype(np.float64))
                placed.append(_Placed(candidate, world_solid, centre, radius, solid.volume * float(np.prod(candidate.scale_vector))))
                break
    stats = PlacementStats(config.num_mushrooms, len(placed), attempts, mesh_tests)
    return [p.instance for p in placed], stats
