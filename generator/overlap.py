"""Placement's overlap test: does a candidate's volume IoU with any neighbour exceed tau?

The answer is always the one exact manifold3d booleans give; certain bounds only spare the
booleans that cannot change it. A boolean costs more the larger the overlap, so each procedural
model also gets two coarse solids of revolution (8 segments): an inner proxy inside it and an
outer proxy containing it, both checked by mesh booleans when built. Because
``vol(inner_A & inner_B) <= vol(A & B) <= vol(outer_A & outer_B)``, a proxy intersection that
clears the IoU threshold by a margin far above round-off decides a pair; every other pair gets
the exact boolean. Pairs are tried deepest first (centre distance over the sum of the bounding
radii), so a rejecting neighbour is usually met first; the order cannot change an "any".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache

import manifold3d
import numpy as np

from generator.config import Species
from generator.mushroom_models import SEGMENTS, MushroomModel, model_library, revolution_arrays

PROXY_SEGMENTS = 8  # around the stem axis: proxies have ~260 triangles, models ~1,500
# Depth (centre distance / radius sum) below which the inner proxies are tried first, and at or
# above which the outer ones are. Measured on pairs of 50- and 100-mushroom beds: below 0.45,
# 75 % of pairs overlap by more than tau and the inner proxies decide half of them; from 0.6, 5 %
# do and the outer proxies decide 90 %; in between a proxy boolean saves less than it costs.
DEEP, SHALLOW = 0.45, 0.6
# Bounds decide only when they clear the threshold by this fraction of the summed volumes.
# manifold3d merges features within its tolerance (about 3.5e-9 m for these float32 meshes),
# which can move a computed volume by up to tolerance x surface area: at most ~1e-6 of the
# volumes here. A hundred times that, a bound never overrules what the boolean would say.
_SAFETY = 1e-4


def _mesh_to_manifold(vertices: np.ndarray, faces: np.ndarray) -> manifold3d.Manifold:
    """A manifold of a closed triangle mesh (float32 vertices), turned outward if it faces in."""
    vertices = np.asarray(vertices, dtype=np.float32)
    faces = np.asarray(faces, dtype=np.uint32)
    a, b, c = (vertices[faces[:, k]].astype(np.float64) for k in range(3))
    if np.einsum("ij,ij->", a, np.cross(b, c)) < 0:  # six times the signed volume
        faces = faces[:, ::-1]
    return manifold3d.Manifold(manifold3d.Mesh(vert_properties=vertices, tri_verts=np.ascontiguousarray(faces)))


def _signed_area(polygon: np.ndarray) -> float:
    """Twice the signed area of a closed polygon (positive when counter-clockwise)."""
    return float(np.sum(polygon[:, 0] * np.roll(polygon[:, 1], -1) - np.roll(polygon[:, 0], -1) * polygon[:, 1]))


def _offset_profile(profile: np.ndarray, delta: float, z_min: float) -> np.ndarray | None:
    """The region a profile sweeps in the (r, z) plane, grown by about ``delta`` (shrunk if
    negative; grown by 1.25 delta, then simplified by delta / 4 to drop vertices) and cut to
    ``z >= z_min``; returned as a profile from pole to pole, or None if it misses the axis."""
    mirrored = np.vstack([profile, (profile * [-1.0, 1.0])[::-1][1:-1]])  # both sides of the axis
    region = manifold3d.CrossSection([mirrored.tolist()])
    if region.area() <= 0:  # clockwise outline
        region = manifold3d.CrossSection([mirrored[::-1].tolist()])
    region = region.offset(delta * 1.25, manifold3d.JoinType.Miter, 4.0).simplify(abs(delta) / 4)
    z_max = float(mirrored[:, 1].max()) + 1.0
    region = region ^ manifold3d.CrossSection.square([1.0, z_max - z_min]).translate([0.0, z_min])
    polygons = [np.asarray(p, dtype=float) for p in region.to_polygons()]
    if not polygons:
        return None
    outline = max(polygons, key=lambda p: abs(_signed_area(p)))
    if _signed_area(outline) < 0:
        outline = outline[::-1]
    on_axis = np.abs(outline[:, 0]) < 1e-9
    if np.count_nonzero(on_axis) < 2:
        return None
    outline[on_axis, 0] = 0.0
    # Counter-clockwise, the outline runs up its outer side and down the axis: start at the
    # lowest point on the axis and stop at the highest.
    axis = np.flatnonzero(on_axis)
    outline = np.roll(outline, -int(axis[np.argmin(outline[axis, 1])]), axis=0)
    axis = np.flatnonzero(outline[:, 0] == 0.0)
    return outline[: int(axis[np.argmax(outline[axis, 1])]) + 1]


def _proxy(model: MushroomModel, exact: manifold3d.Manifold, outer: bool) -> manifold3d.Manifold | None:
    """A coarse solid inside (or, if ``outer``, containing) the model, or None if none is found.

    Both keep to parts whose cross-sections are discs about the stem axis: the inner proxy drops
    the cap below the gills' apex, the outer one fills the hollow under the cap. Then an 8-gon
    inscribed in a proxy's outline lies inside it, and scaling radii up by ``1 / cos(pi / 8)``
    makes the outer proxy's 8-gons contain its outline. The margin covers the model's own
    32-gon chords and the out-of-round ripple; containment is then checked with booleans."""
    if len(model.revolutions) != 2:
        return None
    cap, stem = model.revolutions
    ripple = (1 + 4 * cap.out_of_round) / (1 - cap.out_of_round)
    chord = float(cap.profile[:, 0].max()) * (1 - np.cos(np.pi / SEGMENTS)) * ripple
    widen = (1 + 2e-3) / np.cos(np.pi / PROXY_SEGMENTS)
    for attempt in range(4):
        margin = 1.5**attempt * (1.5 * chord) + 2e-5
        if outer:
            rim = int(np.argmax(cap.profile[:, 0]))
            filled = np.vstack([[0.0, cap.profile[rim, 1]], cap.profile[rim:]])
            outlines = [(_offset_profile(filled, margin, -1.0), cap), (_offset_profile(stem.profile, margin, -1.0), stem)]
        else:
            gills_apex = float(cap.profile[0, 1])
            outlines = [(_offset_profile(cap.profile, -margin, gills_apex + margin), cap),
                        (_offset_profile(stem.profile, -margin, -1.0), stem)]
        if any(outline is None for outline, _ in outlines):
            continue
        parts = []
        for outline, part in outlines:
            if outer:
                outline = outline * [widen, 1.0]
            parts.append(_mesh_to_manifold(*revolution_arrays(outline, part.out_of_round, part.phase, PROXY_SEGMENTS)))
        proxy = parts[0] + parts[1]
        outside = (exact - proxy) if outer else (proxy - exact)
        if outside.volume() == 0.0:
            return proxy
    return None


@dataclass(frozen=True)
class Solid:
    """A model as manifolds (exact, inner and outer proxy, and ``hulls``: the convex hulls of its
    cap and of its stem, the shapes MuJoCo collides) with its bounding sphere and volume."""

    exact: manifold3d.Manifold
    inner: manifold3d.Manifold | None
    outer: manifold3d.Manifold | None
    hulls: manifold3d.Manifold
    centre: np.ndarray  # bounding-box centre, model frame
    radius: float
    volume: float
    pieces: tuple[np.ndarray, ...] = ()  # the convex hull vertices of the cap and of the stem, model frame
    piece_hulls: tuple[manifold3d.Manifold, ...] = ()  # the cap's and the stem's convex hulls
    piece_planes: tuple[np.ndarray, ...] = ()  # their facets' planes (n, d): n . x + d <= 0 inside, model frame


@cache
def model_solid(species: Species, model_id: int) -> Solid:
    model = model_library(species)[model_id]
    exact = _mesh_to_manifold(model.mesh.vertices, model.mesh.faces)
    lo, hi = model.mesh.bounds
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(model.mesh.vertices - centre, axis=1).max())
    from scipy.spatial import ConvexHull

    hulls_of_pieces = [ConvexHull(np.asarray(m.vertices, float)) for m in (model.cap_mesh, model.stem_mesh)]
    pieces = tuple(h.points[h.vertices] for h in hulls_of_pieces)  # the hull's own vertices: the same hull
    planes = tuple(h.equations for h in hulls_of_pieces)
    piece_hulls = tuple(_mesh_to_manifold(m.vertices, m.faces).hull() for m in (model.cap_mesh, model.stem_mesh))
    return Solid(exact, _proxy(model, exact, outer=False), _proxy(model, exact, outer=True),
                 piece_hulls[0] + piece_hulls[1], centre, radius, float(exact.volume()), pieces, piece_hulls, planes)


@dataclass
class Posed:
    """A solid placed by ``affine`` (3 x 4, model to world); its manifolds are moved on first use."""

    solid: Solid
    affine: np.ndarray
    centre: np.ndarray
    radius: float
    volume: float
    _moved: dict[str, manifold3d.Manifold] = field(default_factory=dict, repr=False)
    _points: list[np.ndarray] | None = field(default=None, repr=False)
    _boxes: list[tuple[np.ndarray, np.ndarray]] | None = field(default=None, repr=False)

    @classmethod
    def place(cls, solid: Solid, transform: np.ndarray, scale_vector: np.ndarray) -> Posed:
        """``transform``: the instance's 4 x 4 model-to-world map; ``scale_vector`` its scales."""
        affine = np.asarray(transform[:3], dtype=np.float64)
        centre = transform[:3, :3] @ solid.centre + transform[:3, 3]
        return cls(solid, affine, centre, solid.radius * float(scale_vector.max()),
                   solid.volume * float(np.prod(scale_vector)))

    def piece_points(self) -> list[np.ndarray]:
        """The world-frame vertices of each hull piece (the cap's, the stem's)."""
        if self._points is None:
            rot, shift = self.affine[:, :3], self.affine[:, 3]
            self._points = [v @ rot.T + shift for v in self.solid.pieces]
        return self._points

    def piece_boxes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The world-frame axis-aligned bounding box (low, high corners) of each hull piece."""
        if self._boxes is None:
            self._boxes = [(v.min(axis=0), v.max(axis=0)) for v in self.piece_points()]
        return self._boxes

    def holds_a_point_of(self, piece: int, points: np.ndarray) -> bool:
        """Whether any of ``points`` (world frame) lies strictly inside this solid's hull piece
        ``piece`` (0: the cap, 1: the stem), by 1 µm or more."""
        lo, hi = self.piece_boxes()[piece]
        points = points[np.all((points >= lo) & (points <= hi), axis=1)]  # only these can be inside
        if not len(points):
            return False
        local = np.linalg.solve(self.affine[:, :3], (points - self.affine[:, 3]).T).T
        planes = self.solid.piece_planes[piece]
        # The planes' unit normals are the model frame's; scaling the point back keeps the sign test exact.
        return bool(np.any(np.all(local @ planes[:, :3].T + planes[:, 3] < -1e-6, axis=1)))

    def manifold(self, kind: str) -> manifold3d.Manifold:
        """The ``exact``, ``inner``, ``outer`` or ``hulls`` manifold in the world, or ``"piece0"``
        / ``"piece1"``: the cap's / the stem's convex hull."""
        if kind not in self._moved:
            solid = self.solid.piece_hulls[int(kind[5:])] if kind.startswith("piece") else getattr(self.solid, kind)
            self._moved[kind] = solid.transform(self.affine)
        return self._moved[kind]


def _separated(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether a plane separates the convex hulls of point sets ``a`` and ``b``, tried across the
    line between their centroids and across its horizontal part (a found plane proves them
    apart; none found proves nothing)."""
    d = b.mean(axis=0) - a.mean(axis=0)
    for axis in (d, np.array([d[0], d[1], 0.0])):
        if axis @ axis > 0 and (a @ axis).max() < (b @ axis).min():
            return True
    return False


def intersection_iou(a: manifold3d.Manifold, b: manifold3d.Manifold, volume_a: float, volume_b: float) -> float:
    """Volume IoU of two solids from an exact boolean intersection."""
    inter = (a ^ b).volume()
    union = volume_a + volume_b - inter
    return float(inter / union) if union > 0 else 0.0


@dataclass
class OverlapCounts:
    """Booleans run so far: exact ones and proxy (bound) ones."""

    exact: int = 0
    bounds: int = 0


def _hulls_exceed(a: Posed, b: Posed, tau: float, counts: OverlapCounts) -> bool:
    """Whether the IoU of ``a``'s and ``b``'s collision hulls exceeds ``tau``, as their exact
    boolean decides it. Hull pieces (cap, stem) whose boxes are apart or that a plane separates
    share no volume; with no overlap allowed (``tau`` 0) a piece pair sharing volume decides
    alone, proved by a vertex of one strictly inside the other or else by the pair's boolean
    (cheaper than the whole hulls')."""
    points_a, points_b = a.piece_points(), b.piece_points()
    touching = [(i, j) for i, (lo1, hi1) in enumerate(a.piece_boxes()) for j, (lo2, hi2) in enumerate(b.piece_boxes())
                if np.all(lo1 <= hi2) and np.all(lo2 <= hi1) and not _separated(points_a[i], points_b[j])]
    if not touching:
        return False
    if tau == 0:
        if any(b.holds_a_point_of(j, points_a[i]) or a.holds_a_point_of(i, points_b[j]) for i, j in touching):
            return True
        counts.exact += 1
        return any((a.manifold(f"piece{i}") ^ b.manifold(f"piece{j}")).volume() > 0 for i, j in touching)
    counts.exact += 1
    mine, theirs = a.manifold("hulls"), b.manifold("hulls")
    return intersection_iou(mine, theirs, mine.volume(), theirs.volume()) > tau


def exceeds_iou(candidate: Posed, neighbours: Sequence[Posed], tau: float, counts: OverlapCounts,
                solids: str = "meshes") -> bool:
    """Whether the exact IoU of ``candidate`` with any of ``neighbours`` exceeds ``tau``: of their
    meshes (``solids="meshes"``, the paper's test) or of their collision hulls (``"hulls"``:
    the cap's and the stem's convex hulls, which fill the hollow under the cap)."""
    if solids == "hulls":
        return any(_hulls_exceed(candidate, other, tau, counts) for other in neighbours)
    depth = [float(np.linalg.norm(n.centre - candidate.centre)) / (n.radius + candidate.radius) for n in neighbours]
    for j in sorted(range(len(neighbours)), key=depth.__getitem__):
        other = neighbours[j]
        total = candidate.volume + other.volume
        # IoU = I / (total - I) > tau  <=>  I > tau * total / (1 + tau)
        threshold, safety = tau * total / (1 + tau), _SAFETY * total
        kind = "inner" if depth[j] < DEEP else "outer" if depth[j] >= SHALLOW else None
        if kind is not None and getattr(candidate.solid, kind) is not None and getattr(other.solid, kind) is not None:
            counts.bounds += 1
            bound = (candidate.manifold(kind) ^ other.manifold(kind)).volume()
            if kind == "inner" and bound > threshold + safety:
                return True
            if kind == "outer" and bound < threshold - safety:
                continue
        counts.exact += 1
        if intersection_iou(candidate.manifold("exact"), other.manifold("exact"), candidate.volume, other.volume) > tau:
            return True
    return False
