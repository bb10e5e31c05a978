"""Synthetic mushroom beds (SMS3D section 3.1) as MuJoCo models and RGB-D datasets."""

from generator.config import CameraConfig, PlacementConfig, SceneConfig, TerrainConfig
from generator.errors import ConfigError, MeshError, SceneFormatError
from generator.generate import generate_scene, generate_scene_with_stats
from generator.mesh_loader import load_mushroom_mesh
from generator.mushroom_models import MushroomModel, model_library
from generator.scene import MushroomInstance, Scene
from generator.terrain import Terrain

__all__ = [
    "CameraConfig", "ConfigError", "MeshError", "MushroomInstance", "MushroomModel",
    "PlacementConfig", "Scene", "SceneConfig", "SceneFormatError", "Terrain", "TerrainConfig",
    "generate_scene", "generate_scene_with_stats", "load_mushroom_mesh", "model_library",
]
