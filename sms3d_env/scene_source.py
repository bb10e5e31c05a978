"""Where each reset's bed comes from (the env's ``scene`` argument, read into a
``SceneSourceConfig``): a fixed list of scenes (or a ``sms3d generate`` dataset folder), a pool
of generated beds, or a newly generated bed per reset; and which of its mushrooms can move."""

from __future__ import annotations

import dataclasses
import math
import os
from collections import OrderedDict
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sms3d_env.records import check_int, check_number, record_of

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


@dataclass(frozen=True)
class SceneSourceConfig:
    """Where the beds of ``SMS3DPickEnv`` come from (its ``scene`` argument), and which of their
    mushrooms can move.

    Attributes:
        config: the ``generator.SceneConfig`` of the generated beds, or its mapping form
            (``SceneConfig.from_dict``, e.g. ``{"placement": {"num_mushrooms": 10}}``); None: 25
            mushrooms, the rest the generator's defaults; when mushrooms collide
            (``PickPhysicsParams.mushrooms_collide``), placed with no overlap of their collision
            hulls (``default_scene_config``).
        scenes: a fixed list of ``generator.Scene`` objects, or the folder of a ``sms3d generate``
            dataset (loaded, checksums verified, when the env is made); one is drawn per reset
            (``options={"scene": k}`` picks one). Excludes ``config`` and ``pool``.
        pool: > 0: draw each reset's bed from a pool of this many generated beds (seeds
            ``pool_seed ..``, each generated on first use and kept; the compiled models of the
            most recently drawn beds cached, at most ``MAX_CACHED_MODELS``) instead of generating
            a new one per reset.
        pool_seed: the seed of the pool's first bed.
        free_radius: only mushrooms whose stem base lies within this distance (m) of the
            target's keep a free joint and a root weld (can be disturbed or detached); the others
            are static bodies that the robot passes through, which makes the simulation several
            times faster (the removed ``SMS3DPick-v0`` used 0.10). None (default, v1 and v2): every
            mushroom is free.

    Its mapping form (:func:`~sms3d_env.records.record_of`) has these field names:
    ``{"config": {"placement": {"num_mushrooms": 10}}, "pool": 500}``.
    """

    config: Any = None
    scenes: Any = None
    pool: int = 0
    pool_seed: int = 0
    free_radius: float | None = None

    def __post_init__(self) -> None:
        from generator.config import SceneConfig
        from generator.errors import ConfigError

        if isinstance(self.config, Mapping):
            try:
                object.__setattr__(self, "config", SceneConfig.from_dict(self.config))
            except ConfigError as exc:
                raise ConfigError(f"SceneSourceConfig.config.{exc.field}", exc.message) from None
        if self.config is not None and not isinstance(self.config, SceneConfig):
            raise TypeError(f"SceneSourceConfig.config must be None, a generator.SceneConfig or its mapping form, "
                            f"got {type(self.config).__name__} {self.config!r}")
        if self.scenes is not None and not isinstance(self.scenes, (str, os.PathLike)):
            if not isinstance(self.scenes, Sequence) or isinstance(self.scenes, bytes) or not self.scenes:
                raise ValueError(f"SceneSourceConfig.scenes must be None, a dataset folder or a non-empty list of "
                                 f"generator.Scene, got {self.scenes!r}")
            from generator.scene import Scene

            for k, scene in enumerate(self.scenes):
                if not isinstance(scene, Scene):
                    raise TypeError(f"SceneSourceConfig.scenes[{k}] must be a generator.Scene, got "
                                    f"{type(scene).__name__}")
            object.__setattr__(self, "scenes", tuple(self.scenes))
        check_int("SceneSourceConfig.pool", self.pool)
        check_int("SceneSourceConfig.pool_seed", self.pool_seed)
        if self.scenes is not None and self.config is not None:
            raise ValueError("SceneSourceConfig.config sets the generated beds; with scenes given it would be ignored")
        if self.scenes is not None and self.pool:
            raise ValueError("SceneSourceConfig.pool draws generated beds; with scenes given it would be ignored")
        if self.free_radius is not None:
            check_number("SceneSourceConfig.free_radius", self.free_radius, 1e-9, math.inf,
                         "None or a finite number > 0 (m)")


#: The fields of ``SceneSourceConfig``: a mapping with any of them is its mapping form, any other
#: mapping a ``SceneConfig``'s.
_SOURCE_FIELDS = frozenset(f.name for f in dataclasses.fields(SceneSourceConfig))


#: The placement fields of a bed whose collision hulls do not interpenetrate (mushrooms that collide).
TOUCHING_PLACEMENT = {"overlap_iou": 0.0, "overlap_solids": "hulls"}


def default_scene_config(touching: bool) -> Any:
    """The generated bed when ``scene`` gives none: 25 mushrooms, otherwise the generator's
    defaults; ``touching`` (mushrooms collide): placed so that no two collision hulls
    interpenetrate (``overlap_iou = 0`` on ``"hulls"``), as the paper's 5 % mesh overlap would
    leave hulls up to 16 mm deep in each other."""
    import generator

    cfg = generator.SceneConfig().replace(placement__num_mushrooms=25)
    return cfg.replace(**{f"placement__{k}": v for k, v in TOUCHING_PLACEMENT.items()}) if touching else cfg


def _touching_placement(config: Mapping[str, Any]) -> dict[str, Any]:
    """A ``SceneConfig`` mapping whose placement, where it does not say, leaves no two collision
    hulls interpenetrating (as ``default_scene_config(touching=True)``)."""
    placement = config.get("placement", {})
    if not isinstance(placement, Mapping):
        return dict(config)  # SceneConfig.from_dict names the field
    return {**config, "placement": {**TOUCHING_PLACEMENT, **placement}}


def scene_source_config(scene: Any, touching: bool = False) -> SceneSourceConfig:
    """The env's ``scene`` argument as a ``SceneSourceConfig``: None (a new 25-mushroom bed per
    reset), a ``generator.SceneConfig`` or its mapping form, a list of ``generator.Scene``, a
    dataset folder (``str`` or path), or a ``SceneSourceConfig`` or its mapping form (a mapping
    with any of its field names). ``touching`` (mushrooms collide): a mapping form's placement
    defaults to no overlap of the collision hulls. ``TypeError`` for anything else."""
    from generator.config import SceneConfig

    if scene is None:
        return SceneSourceConfig()
    if isinstance(scene, SceneSourceConfig):
        return scene
    if isinstance(scene, Mapping):
        if _SOURCE_FIELDS & set(scene):
            config = scene.get("config")
            if touching and isinstance(config, Mapping):
                scene = {**scene, "config": _touching_placement(config)}
            return record_of(SceneSourceConfig, scene, "scene")
        return SceneSourceConfig(config=_touching_placement(scene) if touching else scene)
    if isinstance(scene, SceneConfig):
        return SceneSourceConfig(config=scene)
    if isinstance(scene, (str, os.PathLike, Sequence)) and not isinstance(scene, bytes):
        return SceneSourceConfig(scenes=scene)
    raise TypeError(f"scene must be None, a generator.SceneConfig or its mapping form, a list of generator.Scene, "
                    f"a dataset folder or a SceneSourceConfig, got {type(scene).__name__} {scene!r}")


class SceneSource:
    """The beds of ``SMS3DPickEnv``, drawn as its ``SceneSourceConfig`` says.

    Attributes:
        config: that ``SceneSourceConfig``.
        scenes: the fixed scenes (a dataset folder's, loaded with their checksums verified), or None.
        pool: pool slot -> its bed, each generated on first use and kept (a bed is far smaller
            than its compiled model).
        models: (slot, target) -> the compiled world model of a pool bed (``world.build_world``'s
            cache), the ``MAX_CACHED_MODELS`` most recently used.
    """

    def __init__(self, config: SceneSourceConfig, touching: bool = False) -> None:
        self.config, self.touching = config, touching
        placement = None if config.config is None else config.config.placement
        apart = placement is None or all(getattr(placement, k) == v for k, v in TOUCHING_PLACEMENT.items())
        if touching and not apart:
            raise ValueError(
                f"scene: with PickPhysicsParams.mushrooms_collide every mushroom collides with every other, so the "
                f"generated beds must not interpenetrate: give placement.overlap_iou = 0 and placement.overlap_solids "
                f"= 'hulls' (got {placement.overlap_iou!r} and {placement.overlap_solids!r}; the mapping form "
                f"of a scene config sets both by default)")
        scenes = config.scenes
        if isinstance(scenes, (str, os.PathLike)):
            from generator.dataset.readers import load_scenes

            scenes = load_scenes(scenes)
            if not scenes:
                raise ValueError(f"SceneSourceConfig.scenes: the dataset folder {config.scenes} holds no complete scene")
        self.scenes = list(scenes) if scenes is not None else None
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

        cfg = self.config.config
        if cfg is None:
            cfg = default_scene_config(self.touching)
        if not self.config.pool:
            return generator.generate_scene(cfg, seed=int(rng.integers(2**31 - 1))), None
        k = int(rng.integers(self.config.pool))
        if k not in self.pool:
            self.pool[k] = generator.generate_scene(cfg, seed=self.config.pool_seed + k)
        return self.pool[k], k
