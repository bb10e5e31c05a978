"""``generate_scene``: config + seed -> ``Scene`` (terrain, then placement)."""

from __future__ import annotations

import numpy as np

from generator.config import SceneConfig
from generator.errors import ConfigError
from generator.placement import PlacementStats, place_mushrooms
from generator.scene import Scene
from generator.terrain import generate_terrain


def scene_rng(seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """Independent generators for terrain and placement, so changing one leaves the other."""
    terrain_seq, placement_seq = np.random.SeedSequence(seed).spawn(2)
    return np.random.default_rng(terrain_seq), np.random.default_rng(placement_seq)


def generate_scene_with_stats(config: SceneConfig | None = None, seed: int = 0) -> tuple[Scene, PlacementStats]:
    """Like ``generate_scene`` and also returns how placement went."""
    config = config or SceneConfig()
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError("seed", f"must be an integer >= 0, got {seed!r}")
    terrain_rng, placement_rng = scene_rng(int(seed))
    terrain = generate_terrain(config.terrain, terrain_rng)
    instances, stats = place_mushrooms(config.placement, terrain, placement_rng)
    return Scene(config, int(seed), terrain, instances, config.placement.num_mushrooms), stats


def generate_scene(config: SceneConfig | None = None, seed: int = 0) -> Scene:
    """A seeded mushroom bed; the same config and seed give the same scene, byte for byte."""
    return generate_scene_with_stats(config, seed)[0]
