"""Synthetic mushroom beds (SMS3D section 3.1) as MuJoCo models and RGB-D datasets."""

import os

from generator.lazy import lazy_exports

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


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
