"""Synthetic mushroom beds (SMS3D section 3.1) as MuJoCo models and RGB-D datasets."""

import importlib
import os

# Off-screen rendering without a display by default. MuJoCo picks its GL backend when it is first
# imported (generator.geometry does), so this must come before any submodule is loaded.
os.environ.setdefault("MUJOCO_GL", "egl")

#: Public names and the submodules that define them; loaded on first access (PEP 562) so that
#: ``sms3d --help`` and light imports do not pay for trimesh, scipy and MuJoCo.
_EXPORTS = {
    "CameraConfig": "config", "PlacementConfig": "config", "SceneConfig": "config", "TerrainConfig": "config",
    "ConfigError": "errors", "MeshError": "errors", "SceneFormatError": "errors",
    "generate_scene": "generate", "generate_scene_with_stats": "generate",
    "load_mushroom_mesh": "mesh_loader", "MushroomModel": "mushroom_models", "model_library": "mushroom_models",
    "MushroomInstance": "scene", "Scene": "scene", "Terrain": "terrain",
}  # fmt: skip

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'generator' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"generator.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
