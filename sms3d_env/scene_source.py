"""Where each reset's bed comes from: a fixed list of scenes (or a ``sms3d generate`` dataset
folder), a pool of generated beds, or a newly generated bed per reset."""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Hashable, Sequence
from typing import Any

import numpy as np

#: The most compiled world models a pool keeps (the most recently used): one is 4 MB for a
#: 10-mushroom bed and 8 MB for a 25-mushroom one, so a model per bed of a 500-bed pool held
#: gigabytes per env. A model not kept is compiled again on its draw: the same model, so the same
#: episode, for ~60 ms more per reset (25 mushrooms; a copy of a kept one takes ~5 ms).
MAX_CACHED_MODELS = 32


class ModelCache(OrderedDict):
    """``build_world``'s cache of compiled models: a dict that keeps at most ``maxsize`` entries,
    dropping the least recently used."""

    def __init__(self, maxsize: int) -> None:
        if isinstance(maxsize, bool) or not isinstance(maxsize, int) or maxsize < 1:
            raise ValueError(f"maxsize must be an integer >= 1 (an entry is read back once stored), got {maxsize!r}")
        super().__init__()
        self.maxsize = maxsize

    def __reduce__(self) -> tuple[Any, ...]:
        # OrderedDict's own rebuilds with ``cls()``, which has no ``maxsize`` (an env pickled
        # mid-episode carries its cache).
        return type(self), (self.maxsize,), None, None, iter(self.items())

    def __getitem__(self, key: Hashable) -> Any:
        value = super().__getitem__(key)
        self.move_to_end(key)
        return value

    def __setitem__(self, key: Hashable, value: Any) -> None:
        super().__setitem__(key, value)
        self.move_to_end(key)
        while len(self) > self.maxsize:
            self.popitem(last=False)


class SceneSource:
    """The beds of ``SMS3DPickEnv`` (its ``scene_config``, ``scenes``, ``scene_pool`` and
    ``pool_seed`` arguments, checked by :mod:`sms3d_env.env_args`).

    Attributes:
        scenes: the fixed scenes (a dataset folder's, loaded with their checksums verified), or None.
        pool: pool slot -> its bed, each generated on first use and kept (a bed is far smaller
            than its compiled model).
        models: (slot, target) -> the compiled world model of a pool bed (``world.build_world``'s
            cache), the ``MAX_CACHED_MODELS`` most recently used.
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
        self.models = ModelCache(MAX_CACHED_MODELS)

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
