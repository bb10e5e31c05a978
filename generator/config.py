"""Scene configuration: frozen dataclasses validated on construction.

Every default is the SMS3D paper's (section 3.1, Algorithm 1) translated to metres, or the
public code's reading of it where the paper gives no number (see ``shared/reference``).
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


def _require_finite(name: str, value: float) -> None:
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(name, f"must be a finite number, got {value!r}")


def _require_positive(name: str, value: float) -> None:
    _require_finite(name, value)
    if value <= 0:
        raise ConfigError(name, f"must be > 0, got {value!r}")


def _require_range(name: str, lo: float, hi: float, *, positive: bool = True) -> None:
    for suffix, v in (("[0]", lo), ("[1]", hi)):
        (_require_positive if positive else _require_finite)(name + suffix, v)
    if lo > hi:
        raise ConfigError(name, f"min {lo!r} > max {hi!r}")


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
        if not isinstance(self.resolution, int) or self.resolution < 2:
            raise ConfigError("terrain.resolution", f"must be an integer >= 2, got {self.resolution!r}")
        _require_finite("terrain.amplitude", self.amplitude)
        if self.amplitude < 0:
            raise ConfigError("terrain.amplitude", "must be >= 0")
        _require_positive("terrain.scale", self.scale)
        if not isinstance(self.octaves, int) or self.octaves < 1:
            raise ConfigError("terrain.octaves", f"must be an integer >= 1, got {self.octaves!r}")
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
    neighbours: int = 5  # k nearest placed mushrooms checked
    insertion_depth: float = 0.002  # m, stem base sunk below the soil surface

    def __post_init__(self) -> None:
        object.__setattr__(self, "x_range", tuple(self.x_range))
        object.__setattr__(self, "y_range", tuple(self.y_range))
        object.__setattr__(self, "scale_range", tuple(self.scale_range))
        object.__setattr__(self, "stretch_range", tuple(self.stretch_range))
        if not isinstance(self.num_mushrooms, int) or not 1 <= self.num_mushrooms <= 100:
            raise ConfigError("placement.num_mushrooms", f"must be an integer in [1, 100], got {self.num_mushrooms!r}")
        if self.species not in ("white", "brown", "mixed"):
            raise ConfigError("placement.species", f"must be white, brown or mixed, got {self.species!r}")
        _require_range("placement.x_range", *self.x_range, positive=False)
        _require_range("placement.y_range", *self.y_range, positive=False)
        _require_finite("placement.tilt_std_deg", self.tilt_std_deg)
        if not 0 <= self.tilt_std_deg <= 90:
            raise ConfigError("placement.tilt_std_deg", "must be in [0, 90]")
        if self.tilt_distribution not in ("normal", "half_normal"):
            raise ConfigError("placement.tilt_distribution", "must be normal or half_normal")
        _require_range("placement.scale_range", *self.scale_range)
        _require_range("placement.stretch_range", *self.stretch_range)
        if not isinstance(self.max_attempts, int) or self.max_attempts < 1:
            raise ConfigError("placement.max_attempts", "must be an integer >= 1")
        _require_finite("placement.overlap_iou", self.overlap_iou)
        if not 0 <= self.overlap_iou <= 1:
            raise ConfigError("placement.overlap_iou", f"must be in [0, 1], got {self.overlap_iou!r}")
        if not isinstance(self.neighbours, int) or self.neighbours < 1:
            raise ConfigError("placement.neighbours", "must be an integer >= 1")
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
        for name in ("width", "height"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 16:
                raise ConfigError(f"camera.{name}", f"must be an integer >= 16, got {v!r}")
        _require_positive("camera.height_above_soil", self.height_above_soil)
        _require_finite("camera.tilt_deg", self.tilt_deg)
        _require_positive("camera.znear", self.znear)
        _require_positive("camera.zfar", self.zfar)
        if self.znear >= self.zfar:
            raise ConfigError("camera.znear", "must be < camera.zfar")


@dataclass(frozen=True)
class SceneConfig:
    """Everything that, with a seed, determines a scene."""

    terrain: TerrainConfig = field(default_factory=TerrainConfig)
    placement: PlacementConfig = field(default_factory=PlacementConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)

    def __post_init__(self) -> None:
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
        sections = {"terrain": TerrainConfig, "placement": PlacementConfig, "camera": CameraConfig}
        for key, value in data.items():
            if key not in sections:
                raise ConfigError(key, f"unknown section; expected one of {sorted(sections)}")
            section = sections[key]
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
        """Read a YAML or JSON configuration file."""
        import yaml

        try:
            with open(path, encoding="utf-8") as fh:
                data = yaml.safe_load(fh) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise ConfigError(str(path), f"cannot read configuration: {exc}") from exc
        return cls.from_dict(data)

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
