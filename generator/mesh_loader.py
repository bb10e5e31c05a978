"""Load user-supplied mushroom scans (OBJ, STL, PLY, GLB) as ``MushroomModel`` objects."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from generator.config import Species
from generator.errors import MeshError
from generator.mushroom_models import MushroomModel

UNIT_TO_METRES = {"m": 1.0, "cm": 0.01, "mm": 0.001}
_UP_TO_Z = {
    "z": np.eye(3),
    "y": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),  # +y up becomes +z up
    "x": np.array([[0, 0, -1.0], [0, 1, 0], [1, 0, 0]]),
}


def _slab(mesh: trimesh.Trimesh, z_lo: float, z_hi: float) -> trimesh.Trimesh:
    lo, hi = mesh.bounds
    margin = 0.01 * float(np.max(hi - lo)) + 1e-4
    box = trimesh.creation.box(bounds=[[lo[0] - margin, lo[1] - margin, z_lo], [hi[0] + margin, hi[1] + margin, z_hi]])
    return trimesh.boolean.intersection([mesh, box], engine="manifold")


def find_cap_bottom(mesh: trimesh.Trimesh, widening: float = 1.6) -> float:
    """Height at which the mesh first grows ``widening`` times wider than its stem.

    Raises ``MeshError`` when no such height exists (a shape without a clear cap).
    """
    # Surface samples, not vertices: long flat-sided parts have vertices only at their ends.
    points, _ = trimesh.sample.sample_surface(mesh, 20_000, seed=0)
    z = points[:, 2]
    r = np.linalg.norm(points[:, :2], axis=1)
    edges = np.linspace(z.min(), z.max(), 41)
    widths = np.array([r[(z >= a) & (z < b)].max(initial=0.0) for a, b in zip(edges[:-1], edges[1:])])
    stem_width = np.median(widths[1:8][widths[1:8] > 0]) if np.any(widths[1:8] > 0) else 0.0
    wide = np.nonzero(widths > widening * stem_width)[0]
    if stem_width <= 0 or len(wide) == 0 or wide[0] < 2:
        raise MeshError("mesh has no clear cap: its cross-section never widens above a stem")
    return float(edges[wide[0]])


def load_mushroom_mesh(
    path: str | Path,
    species: Species,
    *,
    model_id: int = 0,
    unit: Literal["m", "cm", "mm"] = "mm",
    up_axis: Literal["x", "y", "z"] = "z",
    repair: bool = True,
) -> MushroomModel:
    """Read a scan, convert it to metres with +z up and the stem base at the origin, and split it
    into cap and stem at the height where it widens into a cap.

    With ``repair`` small holes are filled (``trimesh.repair``); a mesh that is still not
    watertight raises ``MeshError``, as does one without a clear cap.
    """
    path = Path(path)
    if unit not in UNIT_TO_METRES:
        raise MeshError(f"unit must be one of {sorted(UNIT_TO_METRES)}, got {unit!r}")
    if up_axis not in _UP_TO_Z:
        raise MeshError(f"up_axis must be x, y or z, got {up_axis!r}")
    try:
        loaded = trimesh.load(path, force="mesh")
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise MeshError(f"{path}: cannot read mesh ({exc})") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(f"{path}: no triangles found")
    mesh = loaded.copy()
    if repair and not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
        trimesh.repair.fix_normals(mesh)
    if not mesh.is_watertight:
        raise MeshError(f"{path}: mesh is not watertight (open boundary edges); repair it or pass a closed mesh")
    transform = np.eye(4)
    transform[:3, :3] = _UP_TO_Z[up_axis] * UNIT_TO_METRES[unit]
    mesh.apply_transform(transform)
    z = mesh.vertices[:, 2]
    base = mesh.vertices[z < z.min() + 0.05 * np.ptp(z)]
    mesh.apply_translation([-base[:, 0].mean(), -base[:, 1].mean(), -z.min()])
    cap_bottom = find_cap_bottom(mesh)
    top = float(mesh.vertices[:, 2].max())
    cap = _slab(mesh, cap_bottom, top + 1.0)
    stem = _slab(mesh, -1.0, cap_bottom)
    r = np.linalg.norm(cap.vertices[:, :2], axis=1)
    return MushroomModel(species, model_id, mesh, cap, stem, float(2 * r.max()), cap_bottom)
