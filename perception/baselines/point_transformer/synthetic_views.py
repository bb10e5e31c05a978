"""Single-mushroom RGB-D views rendered without the scene renderer, for training and tests.

A mushroom mesh (model frame: stem base at the origin, stem axis +z, metres) is posed on a flat
soil plane (``z = 0``) with roll, pitch ~ N(0, σ²), yaw ~ U[0, 2π), ``R = Rz Ry Rx``, a uniform
scale, a per-axis stretch and a small insertion depth, like ``generator.placement``. A pinhole
camera looks straight down from ``camera_height``. Depth is rendered by a point-splat z-buffer:
dense surface samples with back faces culled are projected and each pixel keeps the nearest
depth. Parts below the soil are cut. The depth crop is back-projected with
:func:`perception.pointcloud.depth_to_points`, so views go through the same path as real data.

With ``ViewConfig(camera_model=True)`` the crop, widened by :data:`CAMERA_MODEL_MARGIN_PX` and
with the soil plane behind the mushroom, goes through the dataset's stereo camera model
(:func:`generator.dataset.realism.apply_depth_realism`, every depth effect of ``sms3d generate
--realism``, D405) instead of the white ``depth_noise_std``: correlated and quantised disparity
noise, flying pixels and stereo shadows at the cap's rim, edge holes. The mushroom's own pixels
are kept, so flying pixels on its side of the rim stay in the cloud as they would in a mask.

Meshes come from ``generator.mushroom_models.model_library`` (see :func:`default_models`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cache

import numpy as np
import trimesh
from scipy import ndimage

from generator.camera import Intrinsics
from generator.dataset.options import RealismOptions
from generator.dataset.realism import apply_depth_realism
from generator.geometry import rotation_xyz
from perception.baselines.point_transformer.data import PointCloudSample
from perception.errors import PerceptionConfigError
from perception.pointcloud import MIN_POINTS, depth_to_points

#: World-from-camera rotation for a camera looking straight down (OpenCV axes):
#: camera x = world x, camera y = world −y, camera z = world −z.
CAMERA_FROM_WORLD = np.diag([1.0, -1.0, -1.0])

#: Soil pixels around the mushroom's crop when the camera model is on, so that the rim's
#: neighbour effects (flying pixels, edge holes) see soil on their far side as in a full image.
CAMERA_MODEL_MARGIN_PX = 8

#: Every depth effect of ``sms3d generate --realism`` but the invalid band along the image's left
#: edge: a crop's left edge is not the image's.
_CROP_CAMERA_MODEL = replace(RealismOptions.all_on(), stereo_shadows_left_band=False)


@dataclass(frozen=True)
class ViewConfig:
    """How single-mushroom views are drawn (defaults follow the generator's scene defaults)."""

    width: int = 640
    height: int = 480
    focal_px: float = 382.0  # D405 at 640 x 480
    camera_height: float = 0.40  # m above the soil
    tilt_std_deg: float = 20.0  # σ of roll and pitch
    scale_range: tuple[float, float] = (0.8, 2.0)
    stretch_range: tuple[float, float] = (0.9, 1.1)
    insertion_depth: float = 0.002  # m
    xy_range: float = 0.12  # m, mushroom position uniform in ±xy_range below the camera
    depth_noise_std: float = 0.0005  # m, Gaussian depth noise (unused with camera_model)
    surface_samples: int = 60000
    camera_model: bool = False  # the dataset's D405 stereo camera model instead of depth_noise_std

    def __post_init__(self) -> None:
        for name in ("width", "height", "surface_samples"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 16:
                raise PerceptionConfigError(name, f"must be an int >= 16, got {v!r}")
        for name in ("focal_px", "camera_height"):
            if not getattr(self, name) > 0:
                raise PerceptionConfigError(name, f"must be > 0, got {getattr(self, name)!r}")
        for name in ("tilt_std_deg", "insertion_depth", "xy_range", "depth_noise_std"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise PerceptionConfigError(name, f"must be a finite number >= 0, got {v!r}")
        if not isinstance(self.camera_model, bool):
            raise PerceptionConfigError("camera_model", f"must be a bool, got {self.camera_model!r}")
        for name in ("scale_range", "stretch_range"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                raise PerceptionConfigError(name, f"need 0 < min <= max, got {(lo, hi)!r}")

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics(self.width, self.height, self.focal_px, self.focal_px, self.width / 2.0, self.height / 2.0)


@dataclass(frozen=True)
class MeshModel:
    """A mushroom mesh in its model frame plus what the renderer needs about it."""

    name: str
    mesh: trimesh.Trimesh
    cap_bottom_z: float  # m; points above are coloured as cap
    cap_rgb: tuple[float, float, float] = (0.93, 0.91, 0.86)
    stem_rgb: tuple[float, float, float] = (0.90, 0.88, 0.82)
    cap_diameter: float = 0.03


def default_models(species: Sequence[str] = ("white", "brown"), model_ids: Sequence[int] | None = None) -> list[MeshModel]:
    """The generator's procedural model library as :class:`MeshModel` s."""
    from generator.mushroom_models import model_library

    out = [_mesh_model(m) for sp in species for m in model_library(sp) if model_ids is None or m.model_id in model_ids]
    if not out:
        raise PerceptionConfigError("model_ids", f"no models selected from {list(species)} / {model_ids}")
    return out


def procedural_mesh_models(n_per_species: int, seed: int, species: Sequence[str] = ("white", "brown")) -> list[MeshModel]:
    """``n_per_species`` fresh procedural shapes of each species
    (:func:`generator.mushroom_models.procedural_models`), none of them a library model."""
    from generator.mushroom_models import procedural_models

    return [_mesh_model(m) for sp in species for m in procedural_models(sp, n_per_species, seed)]


def _mesh_model(m) -> MeshModel:
    from generator.mushroom_models import COLOURS

    colours = COLOURS[m.species]
    return MeshModel(m.name, m.mesh, m.cap_bottom_z, tuple(colours["cap"][:3]), tuple(colours["stem"][:3]), m.cap_diameter)


@cache
def _surface(mesh_id: int, mesh: trimesh.Trimesh, n: int) -> tuple[np.ndarray, np.ndarray]:
    pts, face = trimesh.sample.sample_surface(mesh, n, seed=0)
    return np.asarray(pts), np.asarray(mesh.face_normals[face])


def posed_mesh(model: MeshModel, meta: dict) -> trimesh.Trimesh:
    """``model``'s mesh scaled and stretched as a view's ``meta`` records it (model frame, m).
    Rotated by the view's ``rotation`` and placed at its camera-frame position, it lies on the
    view's points."""
    mesh = model.mesh.copy()
    mesh.apply_transform(np.diag([*(meta["scale"] * np.asarray(meta["stretch"])), 1.0]))
    return mesh


def render_view(model: MeshModel, rng: np.random.Generator, config: ViewConfig | None = None) -> PointCloudSample:
    """Render one random view of ``model``; the sample may have fewer than
    :data:`~perception.pointcloud.MIN_POINTS` points (e.g. a mushroom out of view)."""
    cfg = config or ViewConfig()
    roll, pitch = rng.normal(0.0, np.deg2rad(cfg.tilt_std_deg), size=2)
    yaw = rng.uniform(0.0, 2 * np.pi)
    scale = rng.uniform(*cfg.scale_range)
    stretch = rng.uniform(*cfg.stretch_range, size=3)
    xy = rng.uniform(-cfg.xy_range, cfg.xy_range, size=2)
    R_wm = rotation_xyz(roll, pitch, yaw)
    position = np.array([xy[0], xy[1], 0.0]) - cfg.insertion_depth * R_wm[:, 2]

    local, normals = _surface(id(model.mesh), model.mesh, cfg.surface_samples)
    sv = scale * stretch
    pw = (local * sv) @ R_wm.T + position
    nw = (normals / sv) @ R_wm.T  # normals transform by the inverse transpose
    cam = np.array([0.0, 0.0, cfg.camera_height])
    # Keep points above the soil whose normal faces the camera.
    facing = ((cam - pw) * nw).sum(1) > 0
    keep = facing & (pw[:, 2] >= 0.0)
    pw, is_cap = pw[keep], local[keep, 2] >= model.cap_bottom_z
    pc = (pw - cam) @ CAMERA_FROM_WORLD.T
    K = cfg.intrinsics
    z = pc[:, 2]
    u = np.floor(K.fx * pc[:, 0] / z + K.cx).astype(np.int64)
    v = np.floor(K.fy * pc[:, 1] / z + K.cy).astype(np.int64)
    inside = (u >= 0) & (u < cfg.width) & (v >= 0) & (v < cfg.height) & (z > 0)
    u, v, z, is_cap = u[inside], v[inside], z[inside], is_cap[inside]
    R_cm = CAMERA_FROM_WORLD @ R_wm
    meta = {
        "model": model.name,
        "roll": float(roll), "pitch": float(pitch), "yaw": float(yaw),
        "scale": float(scale), "stretch": [float(c) for c in stretch],
        "cap_diameter": float(model.cap_diameter * scale * stretch[:2].mean()),
        "position_world": [float(c) for c in position],
    }  # fmt: skip
    if len(u) == 0:
        return PointCloudSample(np.zeros((0, 3), np.float32), R_cm.astype(np.float32), np.zeros((0, 3), np.float32), meta)
    u0, v0 = u.min(), v.min()
    h, w = v.max() - v0 + 1, u.max() - u0 + 1
    flat = (v - v0) * w + (u - u0)
    depth = np.full(h * w, np.inf)
    np.minimum.at(depth, flat, z)
    # Colour of the nearest sample per pixel (cap or stem), with mild shading noise.
    order = np.lexsort((z, flat))
    first = order[np.r_[True, flat[order][1:] != flat[order][:-1]]]
    cap_px = np.zeros(h * w, bool)
    cap_px[flat[first]] = is_cap[first]
    depth = depth.reshape(h, w)
    valid = np.isfinite(depth)
    cap_px = cap_px.reshape(h, w)
    if cfg.camera_model:
        m = CAMERA_MODEL_MARGIN_PX
        depth, valid, cap_px = (np.pad(a, m) for a in (depth, valid, cap_px))
        u0, v0 = u0 - m, v0 - m
        noisy, _ = apply_depth_realism(_with_soil(depth, valid, cfg.camera_height), cfg.focal_px, "d405",
                                       _CROP_CAMERA_MODEL, rng)
        depth = noisy.astype(np.float64)
        valid &= depth > 0
    elif cfg.depth_noise_std > 0:
        depth = depth + rng.normal(0.0, cfg.depth_noise_std, depth.shape)
    depth[~valid] = 0.0
    rgb = np.where(cap_px[..., None], np.array(model.cap_rgb), np.array(model.stem_rgb))
    rgb = np.clip(rgb * rng.uniform(0.85, 1.0, (*depth.shape, 1)), 0, 1).astype(np.float32)
    crop = Intrinsics(int(depth.shape[1]), int(depth.shape[0]), K.fx, K.fy, K.cx - u0, K.cy - v0)
    points, colors = depth_to_points(depth, crop, valid, rgb)
    return PointCloudSample(points, R_cm.astype(np.float32), colors, meta)


def _with_soil(depth: np.ndarray, valid: np.ndarray, soil_depth: float) -> np.ndarray:
    """``depth`` with the soil plane where no mushroom sample landed outside the mushroom, and
    the nearest mushroom depth in the splat's gaps inside it (pixels no surface sample hit: not
    pits down to the soil, which the camera model would turn into shadows and holes)."""
    inside = ndimage.binary_fill_holes(valid)
    out = np.where(valid, depth, soil_depth)
    gaps = inside & ~valid
    if gaps.any():
        nearest = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
        out[gaps] = depth[nearest[0][gaps], nearest[1][gaps]]
    return out


def generate_samples(
    n: int,
    seed: int,
    models: Sequence[MeshModel] | None = None,
    config: ViewConfig | None = None,
) -> list[PointCloudSample]:
    """``n`` views with at least :data:`MIN_POINTS` points each, models drawn uniformly;
    fully determined by ``seed`` (and the models)."""
    models = list(models) if models is not None else default_models()
    rng = np.random.default_rng(seed)
    out: list[PointCloudSample] = []
    while len(out) < n:
        s = render_view(models[int(rng.integers(len(models)))], rng, config)
        if len(s.points) >= MIN_POINTS:
            out.append(s)
    return out
