"""Procedural mushroom models: watertight meshes in metres with a cap, gills and a stem.

A model's frame has its origin at the centre of the stem base and +z along the stem axis, from
the stem base towards the cap. Each model is the union (a real mesh boolean) of two watertight
solids of revolution: a stem and a cap with a gill underside, both slightly out of round.
Proportions follow ``docs/physics.md`` (measured mushrooms): stems about a third of the cap
diameter thick, caps about 0.55 of their diameter high, caps out of round by up to ~10 %.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache, cached_property

import numpy as np
import trimesh

from generator.config import Species

MODELS_PER_SPECIES = 7
SEGMENTS = 32  # mesh segments around the stem axis

# Mass from cap diameter D in mm, m = a * D**b grams (log-log fits of measured mushrooms).
MASS_FIT = {"white": (1.464e-3, 2.500), "brown": (1.681e-3, 2.508)}
# RGBA of cap top, gills and stem (linear 0..1).
COLOURS = {
    "white": {"cap": (0.93, 0.91, 0.86, 1.0), "stem": (0.90, 0.88, 0.82, 1.0)},
    "brown": {"cap": (0.55, 0.38, 0.26, 1.0), "stem": (0.84, 0.78, 0.70, 1.0)},
}


@dataclass(frozen=True)
class Revolution:
    """How ``revolve`` made a part: its profile ``(r, z)`` from pole to pole and its out-of-round
    amplitude and phase (the mesh has ``SEGMENTS`` segments)."""

    profile: np.ndarray
    out_of_round: float
    phase: float


@dataclass(frozen=True)
class MushroomModel:
    """One mushroom model in its own frame (stem base at the origin, stem axis +z)."""

    species: Species
    model_id: int
    mesh: trimesh.Trimesh  # whole mushroom, watertight
    cap_mesh: trimesh.Trimesh  # cap alone, watertight
    stem_mesh: trimesh.Trimesh  # stem alone, watertight
    cap_diameter: float  # m, mean of the cap's largest and smallest diameters
    cap_bottom_z: float  # m, height of the cap rim above the stem base
    # Cap and stem as solids of revolution (procedural models); empty for scanned meshes.
    revolutions: tuple[Revolution, ...] = field(default=(), compare=False, repr=False)

    @property
    def name(self) -> str:
        return f"{self.species}_{self.model_id}"

    @property
    def stem_base(self) -> np.ndarray:
        return np.zeros(3)

    @property
    def stem_axis(self) -> np.ndarray:
        return np.array([0.0, 0.0, 1.0])

    # Cached: every placement attempt reads them, and trimesh re-hashes a mesh on each access.
    @cached_property
    def cap_top_z(self) -> float:
        return float(self.cap_mesh.vertices[:, 2].max())

    @cached_property
    def cap_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre and edge lengths of the cap's box, axis-aligned in the model frame (read-only)."""
        lo, hi = self.cap_mesh.bounds
        centre, size = (lo + hi) / 2.0, hi - lo
        centre.flags.writeable = size.flags.writeable = False
        return centre, size


def revolve(profile: np.ndarray, out_of_round: float, phase: float, segments: int = SEGMENTS) -> trimesh.Trimesh:
    """A watertight solid of revolution about +z from a profile ``(r, z)`` running from the bottom
    pole (r = 0) to the top pole (r = 0); the radius is scaled by ``1 + e cos(2 (phi - phase))``."""
    mesh = trimesh.Trimesh(*revolution_arrays(profile, out_of_round, phase, segments), process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def revolution_arrays(profile: np.ndarray, out_of_round: float, phase: float,
                      segments: int = SEGMENTS) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of ``revolve``'s solid, before any orientation fix."""
    if profile[0, 0] != 0 or profile[-1, 0] != 0:
        raise ValueError("profile must start and end on the axis (r = 0)")
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    radial = 1.0 + out_of_round * np.cos(2 * (phi - phase))
    ring = profile[1:-1]
    n_rings = len(ring)
    verts = [np.array([0.0, 0.0, profile[0, 1]])]
    for r, z in ring:
        verts.extend(np.stack([r * radial * np.cos(phi), r * radial * np.sin(phi), np.full(segments, z)], 1))
    verts.append(np.array([0.0, 0.0, profile[-1, 1]]))
    vertices = np.vstack(verts)
    top = len(vertices) - 1
    faces = []
    seg = np.arange(segments)
    nxt = (seg + 1) % segments
    first = 1 + seg
    faces.append(np.stack([np.zeros(segments, int), 1 + nxt, first], 1))
    for k in range(n_rings - 1):
        a, b = 1 + k * segments + seg, 1 + k * segments + nxt
        c, d = a + segments, b + segments
        faces.append(np.stack([a, b, d], 1))
        faces.append(np.stack([a, d, c], 1))
    last = 1 + (n_rings - 1) * segments
    faces.append(np.stack([last + seg, last + nxt, np.full(segments, top)], 1))
    return vertices, np.vstack(faces)


def _cap_profile(radius: float, height: float, rim_z: float, stem_radius: float, gill_depth: float) -> np.ndarray:
    """Cap outline: a flattened dome on a gill underside recessed by ``gill_depth``."""
    t = np.linspace(0, np.pi / 2, 14)
    dome = np.stack([radius * np.cos(t), rim_z + height * np.sin(t) ** 0.8], 1)
    underside_r = np.linspace(stem_radius * 0.6, radius * 0.92, 6)
    # The gills sit higher towards the rim's inside, then the rim curls down to ``rim_z``.
    underside_z = rim_z + gill_depth * (1 - ((underside_r - stem_radius * 0.6) / radius) ** 2)
    bottom = np.array([[0.0, rim_z + gill_depth]])
    return np.vstack([bottom, np.stack([underside_r, underside_z], 1), dome[:-1], [[0.0, rim_z + height]]])


def _stem_profile(radius: float, top_z: float) -> np.ndarray:
    """Stem outline: slightly wider at the base, rounded bottom edge."""
    return np.array([
        [0.0, 0.0], [radius * 1.05, 0.0], [radius * 1.12, 0.002], [radius * 1.0, top_z * 0.5],
        [radius * 0.95, top_z], [0.0, top_z],
    ])


def build_model(species: Species, model_id: int, rng: np.random.Generator) -> MushroomModel:
    """Draw one mushroom's proportions from ``rng`` and build its meshes (unit scale ~ 25-40 mm cap)."""
    diameter = rng.uniform(0.025, 0.040)
    radius = diameter / 2
    cap_height = diameter * rng.uniform(0.45, 0.6)
    stem_radius = diameter * rng.uniform(0.15, 0.2)
    rim_z = diameter * rng.uniform(0.35, 0.6)  # visible stem length below the rim
    gill_depth = cap_height * 0.25
    out_of_round = rng.uniform(0.0, 0.05) if species == "white" else rng.uniform(0.0, 0.07)
    phase = rng.uniform(0, np.pi)
    parts = (Revolution(_cap_profile(radius, cap_height, rim_z, stem_radius, gill_depth), out_of_round, phase),
             # The stem reaches into the cap so the union is one connected solid.
             Revolution(_stem_profile(stem_radius, rim_z + gill_depth * 1.5), out_of_round / 2, phase))
    cap, stem = (revolve(part.profile, part.out_of_round, part.phase) for part in parts)
    whole = trimesh.boolean.union([cap, stem], engine="manifold")
    if not (cap.is_watertight and stem.is_watertight and whole.is_watertight):
        raise RuntimeError(f"procedural model {species}_{model_id} is not watertight")
    return MushroomModel(species, model_id, whole, cap, stem, diameter, rim_z, parts)


@cache
def model_library(species: Species) -> tuple[MushroomModel, ...]:
    """The built-in models of a species (fixed seed: the same meshes on every machine)."""
    rng = np.random.default_rng(_species_index(species))
    return tuple(build_model(species, i, rng) for i in range(MODELS_PER_SPECIES))


def _species_index(species: str) -> int:
    if species not in COLOURS:
        raise ValueError(f"unknown species {species!r}; expected 'white' or 'brown'")
    return 0 if species == "white" else 1


def procedural_models(species: Species, n: int, seed: int) -> tuple[MushroomModel, ...]:
    """``n`` more models of ``species`` drawn like the library's, from their own seed stream.

    For training pose networks on many shapes rather than the library's seven; ids continue
    after the library's (``MODELS_PER_SPECIES``, ...), and no seed reproduces a library model.
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"n: must be an int >= 1, got {n!r}")
    rng = np.random.default_rng([seed, _species_index(species), 1])
    return tuple(build_model(species, MODELS_PER_SPECIES + i, rng) for i in range(n))


def mushroom_mass(species: Species, cap_diameter: float) -> float:
    """Fresh mass in kg from the cap diameter in metres (measured log-log fit)."""
    a, b = MASS_FIT[species]
    return a * (cap_diameter * 1000.0) ** b / 1000.0
