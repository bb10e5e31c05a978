"""Scene configuration: frozen dataclasses validated on construction.

Every default is the SMS3D paper's (section 3.1, Algorithm 1) translated to metres, or the
public code's reading of it where the paper gives no number; ``docs/physics.md`` gives the
sources of the physical values.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from generator.errors import ConfigError

Species = Literal["white", "brown"]
SpeciesMix = Literal["white", "brown", "mixed"]
TiltDistribution = Literal["normal", "half_normal"]


# Upper bounds that keep one scene within seconds and a few hundred MiB. 1024 grid points give
# 0.7 mm soil spacing on the default 0.7 m patch, finer than the ~1 mm a pixel covers at 0.4 m
# (terrain generation then peaks near 200 MiB; 2048 takes 700 MiB and 100000 would need 74 GiB).
MAX_TERRAIN_RESOLUTION = 1024
# Octave 16 at the default lacunarity has a wavelength of microns, and every octave is one more
# pass over the grid.
MAX_OCTAVES = 16
# 100x the paper's M: more only makes a crowded request fail slower.
MAX_ATTEMPTS = 10_000
# The largest real modes are 1280 x 720 (D405) and 1920 x 1080 (D435 colour); beyond 4096 the
# off-screen frame buffers exceed what common GL drivers allocate (100000 fails inside MuJoCo).
MIN_IMAGE_SIDE, MAX_IMAGE_SIDE = 16, 4096


def is_number(value: Any) -> bool:
    # bool is an int subclass: ``amplitude: true`` must not read as 1.0 m.
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _require_finite(name: str, value: float) -> None:
    if not is_number(value) or not math.isfinite(value):
        raise ConfigError(name, f"must be a finite number, got {value!r}")


def _require_positive(name: str, value: float) -> None:
    _require_finite(name, value)
    if value <= 0:
        raise ConfigError(name, f"must be > 0, got {value!r}")


def require_int(name: str, value: Any, lo: int, hi: int | None = None) -> int:
    """``value`` if it is an integer (not a bool) in ``[lo, hi]``, else ``ConfigError(name)``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < lo or (hi is not None and value > hi):
        bounds = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise ConfigError(name, f"must be an integer {bounds}, got {value!r}")
    return value


def require_image_side(name: str, value: Any) -> int:
    """An image width or height in pixels."""
    return require_int(name, value, MIN_IMAGE_SIDE, MAX_IMAGE_SIDE)


def _require_range(name: str, value: Any, *, positive: bool = True) -> tuple[float, float]:
    """``value`` as a ``(min, max)`` tuple of finite numbers (> 0 if ``positive``)."""
    try:
        pair = tuple(value) if not isinstance(value, (str, bytes, Mapping)) else None
    except TypeError:
        pair = None
    if pair is None or len(pair) != 2:
        raise ConfigError(name, f"must be a pair [min, max], got {value!r}")
    for suffix, v in zip(("[0]", "[1]"), pair):
        (_require_positive if positive else _require_finite)(name + suffix, v)
    if pair[0] > pair[1]:
        raise ConfigError(name, f"min {pair[0]!r} > max {pair[1]!r}")
    return pair


@dataclass(frozen=True)
class TerrainConfig:
    """Perlin fBm soil: ``z(x, y) = A * sum_o p**o * n(L**o * s * x, L**o * s * y) + z0``."""

    size_x: float = 0.7  # m, patch extent along x (wider than the placement range so the camera sees soil)
    size_y: float = 0.7  # m
    resolution: int = 160  # grid points along each axis (the paper's R_I = R_J), ~4.4 mm spacing
    amplitude: float = 0.008  # m, the paper's A
    scale: float = 8.0  # 1/m, the paper's s (features of ~1/s = 12 cm)
    octaves: int = 6  # O
    persistence: float = 0.5  # p
    lacunarity: float = 2.0
    base_elevation: float = 0.0  # m, z0

    def __post_init__(self) -> None:
        _require_positive("terrain.size_x", self.size_x)
        _require_positive("terrain.size_y", self.size_y)
        require_int("terrain.resolution", self.resolution, 2, MAX_TERRAIN_RESOLUTION)
        _require_finite("terrain.amplitude", self.amplitude)
        if self.amplitude < 0:
            raise ConfigError("terrain.amplitude", "must be >= 0")
        _require_positive("terrain.scale", self.scale)
        require_int("terrain.octaves", self.octaves, 1, MAX_OCTAVES)
        _require_positive("terrain.persistence", self.persistence)
        _require_positive("terrain.lacunarity", self.lacunarity)
        _require_finite("terrain.base_elevation", self.base_elevation)


@dataclass(frozen=True)
class PlacementConfig:
    """The paper's Algorithm 1 parameters."""

    num_mushrooms: int = 30
    species: SpeciesMix = "mixed"
    x_range: tuple[float, float] = (-0.18, 0.18)  # m
    y_range: tuple[float, float] = (-0.18, 0.18)  # m
    tilt_std_deg: float = 20.0  # sigma of roll and pitch
    tilt_distribution: TiltDistribution = "normal"  # "half_normal" = the public code's abs(gauss)
    scale_range: tuple[float, float] = (0.8, 2.0)  # uniform s, applied to ~30 mm base models
    stretch_range: tuple[float, float] = (0.9, 1.1)  # per-axis epsilon in the mushroom frame
    max_attempts: int = 100  # M
    overlap_iou: float = 0.05  # tau
    neighbours: int = 5  # k nearest placed mushrooms checked (with "meshes")
    # "meshes": the paper's IoU of the meshes; "hulls": of the convex hulls of cap and stem that
    # MuJoCo collides, against every mushroom whose bounding sphere touches (with overlap_iou = 0,
    # a bed whose collision shapes do not interpenetrate at rest).
    overlap_solids: Literal["meshes", "hulls"] = "meshes"
    insertion_depth: float = 0.002  # m, stem base sunk below the soil surface

    def __post_init__(self) -> None:
        require_int("placement.num_mushrooms", self.num_mushrooms, 1, 100)
        if self.species not in ("white", "brown", "mixed"):
            raise ConfigError("placement.species", f"must be white, brown or mixed, got {self.species!r}")
        for name, positive in (("x_range", False), ("y_range", False), ("scale_range", True), ("stretch_range", True)):
            pair = _require_range(f"placement.{name}", getattr(self, name), positive=positive)
            object.__setattr__(self, name, pair)
        _require_finite("placement.tilt_std_deg", self.tilt_std_deg)
        if not 0 <= self.tilt_std_deg <= 90:
            raise ConfigError("placement.tilt_std_deg", "must be in [0, 90]")
        if self.tilt_distribution not in ("normal", "half_normal"):
            raise ConfigError("placement.tilt_distribution", "must be normal or half_normal")
        require_int("placement.max_attempts", self.max_attempts, 1, MAX_ATTEMPTS)
        _require_finite("placement.overlap_iou", self.overlap_iou)
        if not 0 <= self.overlap_iou <= 1:
            raise ConfigError("placement.overlap_iou", f"must be in [0, 1], got {self.overlap_iou!r}")
        require_int("placement.neighbours", self.neighbours, 1, 100)  # more than num_mushrooms can hold
        if self.overlap_solids not in ("meshes", "hulls"):
            raise ConfigError("placement.overlap_solids", f"must be meshes or hulls, got {self.overlap_solids!r}")
        _require_finite("placement.insertion_depth", self.insertion_depth)
        if not 0 <= self.insertion_depth <= 0.02:
            raise ConfigError("placement.insertion_depth", "must be in [0, 0.02] m")


@dataclass(frozen=True)
class CameraConfig:
    """Overhead RGB-D camera; ``preset`` picks RealSense-like intrinsics at 640 x 480."""

    preset: Literal["d405", "d435"] = "d405"
    width: int = 640
    height: int = 480
    height_above_soil: float = 0.40  # m, inside a D405's best range (7-50 cm)
    tilt_deg: float = 0.0  # rotation about the camera's x axis away from straight down
    znear: float = 0.05
    zfar: float = 2.0

    def __post_init__(self) -> None:
        if self.preset not in ("d405", "d435"):
            raise ConfigError("camera.preset", f"must be d405 or d435, got {self.preset!r}")
        require_image_side("camera.width", self.width)
        require_image_side("camera.height", self.height)
        _require_positive("camera.height_above_soil", self.height_above_soil)
        _require_finite("camera.tilt_deg", self.tilt_deg)
        _require_positive("camera.znear", self.znear)
        _require_positive("camera.zfar", self.zfar)
        if self.znear >= self.zfar:
            raise ConfigError("camera.znear", "must be < camera.zfar")


_SECTIONS = {"terrain": TerrainConfig, "placement": PlacementConfig, "camera": CameraConfig}


@dataclass(frozen=True)
class SceneConfig:
    """Everything that, with a seed, determines a scene."""

    terrain: TerrainConfig = field(default_factory=TerrainConfig)
    placement: PlacementConfig = field(default_factory=PlacementConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)

    def __post_init__(self) -> None:
        for name, section in _SECTIONS.items():
            if not isinstance(getattr(self, name), section):
                raise ConfigError(name, f"must be a {section.__name__}, got {type(getattr(self, name)).__name__}")
        p, t = self.placement, self.terrain
        if (p.x_range[0] < -t.size_x / 2 or p.x_range[1] > t.size_x / 2
                or p.y_range[0] < -t.size_y / 2 or p.y_range[1] > t.size_y / 2):
            raise ConfigError("placement.x_range", "placement range must lie inside the terrain patch")
        # ~20 mm is the smallest footprint of a mushroom at the smallest scale: a crude but
        # honest bound that rejects requests no placement could satisfy.
        area = (p.x_range[1] - p.x_range[0] + 0.04) * (p.y_range[1] - p.y_range[0] + 0.04)
        if p.num_mushrooms * (0.02 * p.scale_range[0]) ** 2 > area:
            raise ConfigError("placement.num_mushrooms", f"{p.num_mushrooms} mushrooms cannot fit in a {area:.4f} m^2 patch")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SceneConfig:
        """Build from a nested mapping (JSON/YAML); unknown keys raise ``ConfigError``."""
        if not isinstance(data, Mapping):
            raise ConfigError("config", f"must be a mapping, got {type(data).__name__}")
        parts: dict[str, Any] = {}
        for key, value in data.items():
            if key not in _SECTIONS:
                raise ConfigError(str(key), f"unknown section; expected one of {sorted(_SECTIONS)}")
            section = _SECTIONS[key]
            names = {f.name for f in dataclasses.fields(section)}
            if not isinstance(value, Mapping):
                raise ConfigError(key, "must be a mapping")
            for k in value:
                if k not in names:
                    raise ConfigError(f"{key}.{k}", "unknown field")
            try:
                parts[key] = section(**value)
            except TypeError as exc:  # a wrong type that the validators did not catch
                raise ConfigError(key, str(exc)) from exc
        return cls(**parts)

    @classmethod
    def from_file(cls, path: str) -> SceneConfig:
        """Read a YAML or JSON configuration file (see :mod:`generator.config_file`)."""
        from generator.config_file import read_config_file

        return cls.from_dict(read_config_file(path))

    def replace(self, **sections: Any) -> SceneConfig:
        """A copy with whole sections or ``section__field=value`` overrides replaced."""
        updates: dict[str, Any] = {}
        for key, value in sections.items():
            if "__" in key:
                sec, name = key.split("__", 1)
                current = updates.get(sec, getattr(self, sec))
                updates[sec] = dataclasses.replace(current, **{name: value})
            else:
                updates[key] = value
        return dataclasses.replace(self, **updates)
