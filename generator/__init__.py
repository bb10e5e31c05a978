"""Synthetic mushroom beds (SMS3D section 3.1) as MuJoCo models and RGB-D datasets."""

import os

# Off-screen rendering without a display by default. MuJoCo picks its GL backend when it is first
# imported, which the imports below do, so this must come first.
os.environ.setdefault("MUJOCO_GL", "egl")

from generator.config import CameraConfig, PlacementConfig, SceneConfig, TerrainConfig  # noqa: E402
from generator.errors import ConfigError, MeshError, SceneFormatError  # noqa: E402
from generator.generate import generate_scene, generate_scene_with_stats  # noqa: E402
from generator.mesh_loader import load_mushroom_mesh  # noqa: E402
from generator.mushroom_models import MushroomModel, model_library  # noqa: E402
from generator.scene import MushroomInstance, Scene  # noqa: E402
from generator.terrain import Terrain  # noqa: E402

__all__ = [
    "CameraConfig", "ConfigError", "MeshError", "MushroomInstance", "MushroomModel",
    "PlacementConfig", "Scene", "SceneConfig", "SceneFormatError", "Terrain", "TerrainConfig",
    "generate_scene", "generate_scene_with_stats", "load_mushroom_mesh", "model_library",
]
