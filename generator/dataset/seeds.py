"""Per-scene seeds and split choice, derived from the run seed and the scene index only, so
output never depends on the number of workers or on the order scenes finish in."""

from __future__ import annotations

import numpy as np

SPLITS = ("train", "val", "test")
_SCENE, _REALISM, _SPLIT = 0, 1, 2


def scene_seed(run_seed: int, index: int) -> int:
    """The ``generate_scene`` seed of scene ``index`` (a 32-bit integer)."""
    return int(np.random.SeedSequence([run_seed, index, _SCENE]).generate_state(1)[0])


def realism_rng(run_seed: int, index: int) -> np.random.Generator:
    """Generator for the realism draws (noise, lighting, jitter) of scene ``index``."""
    return np.random.default_rng(np.random.SeedSequence([run_seed, index, _REALISM]))


def split_of(run_seed: int, index: int, ratios: tuple[float, float, float]) -> str:
    """``train``, ``val`` or ``test``, drawn with probabilities ``ratios / sum(ratios)``."""
    u = np.random.default_rng(np.random.SeedSequence([run_seed, index, _SPLIT])).random()
    cumulative = np.cumsum(np.asarray(ratios, dtype=float)) / float(sum(ratios))
    return SPLITS[min(int(np.searchsorted(cumulative, u, side="right")), 2)]
