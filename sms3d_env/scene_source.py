"""Where each reset's bed comes from: a fixed list of scenes (or a ``sms3d generate`` dataset
folder), a pool of generated beds, or a newly generated bed per reset."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import mujoco


class SceneSource:
    """The beds of ``SMS3DPickEnv`` (its ``scene_config``, ``scenes``, ``scene_pool`` and
    ``pool_seed`` arguments, checked by :mod:`sms3d_env.env_args`).

    Attributes:
        scenes: the fixed scenes (a dataset folder's, loaded with their checksums verified), or None.
        pool: pool slot -> its bed, each generated on first use and kept.
        models: (slot, target) -> the compiled world model of a pool bed (``world.build_world``'s cache).
    """

    def __init__(self, scene_config: Any = None, scenes: Sequence[Any] | str | os.PathLike | None = None,
                 scene_pool: int = 0, pool_seed: int = 0) -> None:
        if isinstance(scenes, (str, os.PathLike)):
            from generator.dataset.readers import load_scenes

            scenes = load_scenes(scenes)
            if not scenes:
                raise ValueError("scenes: the dataset folder holds no complete scene")
        self.scenes = list(scenes) if scenes is not None else None
        self.scene_config = scene_config
        self.scene_pool, self.pool_seed = scene_pool, pool_seed
        self.pool: dict[int, Any] = {}
        self.models: dict[tuple[int, int], mujoco.MjModel] = {}

    def draw(self, rng: np.random.Generator, options: dict[str, Any]) -> tuple[Any, int | None]:
        """The reset's scene (``options["scene"]`` picks a fixed one), and its pool slot (None
        outside a pool)."""
        if self.scenes is not None:
            k = options.get("scene")
            k = int(rng.integers(len(self.scenes))) if k is None else int(k)
            return self.scenes[k], None
        import generator

        cfg = self.scene_config
        if cfg is None:
            cfg = generator.SceneConfig().replace(placement__num_mushrooms=25)
        if not self.scene_pool:
            return generator.generate_scene(cfg, seed=int(rng.integers(2**31 - 1))), None
        k = int(rng.integers(self.scene_pool))
        if k not in self.pool:
            self.pool[k] = generator.generate_scene(cfg, seed=self.pool_seed + k)
        return self.pool[k], k
