"""The ``Scene`` data model: terrain, placed mushrooms and their 3D annotations, as exact JSON."""

from __future__ import annotations

import base64
import binascii
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from generator.config import SceneConfig, Species
from generator.errors import SceneFormatError
from generator.files import write_atomic
from generator.geometry import OrientedBox
from generator.mushroom_models import MushroomModel, model_library
from generator.terrain import Terrain

# 2: terrain heights as base64 of little-endian float64 (exact, ~3x smaller and far faster to
# write than JSON numbers); version 1 files, with heights as nested lists, still load.
SCHEMA_VERSION = 2
_READABLE_VERSIONS = (1, 2)


def encode_heights(heights: np.ndarray) -> dict[str, Any]:
    """A height grid as JSON: shape, dtype and the base64 of its little-endian float64 bytes."""
    raw = np.ascontiguousarray(heights, dtype="<f8").tobytes()
    return {"dtype": "<f8", "shape": list(heights.shape), "base64": base64.b64encode(raw).decode("ascii")}


def decode_heights(data: Any, schema_version: int) -> np.ndarray:
    """Inverse of ``encode_heights``; schema version 1 stored nested lists of floats."""
    if schema_version == 1:
        return np.asarray(data, dtype=float)
    if not isinstance(data, dict) or data.get("dtype") != "<f8":
        raise SceneFormatError("terrain.heights: expected {'dtype': '<f8', 'shape': ..., 'base64': ...}")
    try:
        values = np.frombuffer(base64.b64decode(data["base64"], validate=True), dtype="<f8")
        shape = tuple(int(n) for n in data["shape"])
    except (binascii.Error, KeyError, TypeError, ValueError) as exc:
        raise SceneFormatError(f"terrain.heights: cannot decode ({exc})") from exc
    if len(shape) != 2 or values.size != shape[0] * shape[1]:
        raise SceneFormatError(f"terrain.heights: {values.size} values do not fill shape {list(shape)}")
    return values.reshape(shape).astype(float)


@dataclass(frozen=True)
class MushroomInstance:
    """A placed mushroom. World point = ``rotation @ (scale * stretch * p_model) + position``."""

    id: int
    species: Species
    model_id: int
    position: np.ndarray  # world position of the model frame's origin (centre of the stem base)
    rotation: np.ndarray  # (3, 3) model frame -> world
    scale: float
    stretch: np.ndarray  # (3,) per-axis stretch in the model frame
    stem_base: np.ndarray  # point where the stem axis meets the soil surface
    cap_top: np.ndarray  # top of the cap on the stem axis
    cap_obb: OrientedBox
    cap_diameter: float  # m, after scaling
    mass: float  # kg

    @property
    def stem_axis(self) -> np.ndarray:
        """Unit vector from stem base to cap (the model's +z in the world)."""
        return self.rotation[:, 2].copy()

    @property
    def scale_vector(self) -> np.ndarray:
        return self.scale * np.asarray(self.stretch)

    @property
    def transform(self) -> np.ndarray:
        """4 x 4 affine map from model to world coordinates (``T = [R S | p]``)."""
        t = np.eye(4)
        t[:3, :3] = self.rotation * self.scale_vector
        t[:3, 3] = self.position
        return t

    @property
    def model(self) -> MushroomModel:
        return model_library(self.species)[self.model_id]

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "species": self.species,
            "model_id": self.model_id,
            "position": self.position.tolist(),
            "rotation": self.rotation.tolist(),
            "scale": self.scale,
            "stretch": np.asarray(self.stretch).tolist(),
            "stem_axis": self.stem_axis.tolist(),
            "stem_base": self.stem_base.tolist(),
            "cap_top": self.cap_top.tolist(),
            "cap_obb": self.cap_obb.to_dict(),
            "cap_diameter": self.cap_diameter,
            "mass": self.mass,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MushroomInstance:
        arr = lambda key: np.asarray(data[key], dtype=float)  # noqa: E731
        return cls(
            id=int(data["id"]),
            species=data["species"],
            model_id=int(data["model_id"]),
            position=arr("position"),
            rotation=arr("rotation"),
            scale=float(data["scale"]),
            stretch=arr("stretch"),
            stem_base=arr("stem_base"),
            cap_top=arr("cap_top"),
            cap_obb=OrientedBox.from_dict(data["cap_obb"]),
            cap_diameter=float(data["cap_diameter"]),
            mass=float(data["mass"]),
        )


@dataclass(frozen=True)
class Scene:
    """A generated mushroom bed: the config and seed that made it, its soil and its mushrooms."""

    config: SceneConfig
    seed: int
    terrain: Terrain
    instances: list[MushroomInstance] = field(default_factory=list)
    requested: int = 0  # mushrooms asked for; ``len(instances)`` may be fewer

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema_version": SCHEMA_VERSION,
            "seed": self.seed,
            "config": self.config.to_dict(),
            "requested": self.requested,
            "terrain": {
                "size_x": self.terrain.size_x,
                "size_y": self.terrain.size_y,
                "heights": encode_heights(self.terrain.heights),
            },
            "instances": [m.to_dict() for m in self.instances],
        }

    def to_json(self) -> str:
        """Deterministic JSON text (floats written with ``repr``, so reading back is exact)."""
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scene:
        version = data.get("schema_version")
        if version not in _READABLE_VERSIONS:
            raise SceneFormatError(f"unsupported scene schema_version {version!r} (this version reads "
                                   f"{', '.join(map(str, _READABLE_VERSIONS))})")
        terrain = data["terrain"]
        heights = decode_heights(terrain["heights"], version)
        return cls(
            config=SceneConfig.from_dict(data["config"]),
            seed=int(data["seed"]),
            terrain=Terrain(heights, float(terrain["size_x"]), float(terrain["size_y"])),
            instances=[MushroomInstance.from_dict(m) for m in data["instances"]],
            requested=int(data["requested"]),
        )

    @classmethod
    def from_json(cls, text: str) -> Scene:
        try:
            return cls.from_dict(json.loads(text))
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, SceneFormatError):
                raise
            raise SceneFormatError(f"not a valid scene: {exc}") from exc

    def save(self, path: str | Path) -> None:
        """Write atomically (temporary file, then rename)."""
        write_atomic(path, self.to_json())

    @classmethod
    def load(cls, path: str | Path) -> Scene:
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise SceneFormatError(f"{path}: cannot read ({exc})") from exc
        try:
            return cls.from_json(text)
        except SceneFormatError as exc:
            raise SceneFormatError(f"{path}: {exc}") from exc
