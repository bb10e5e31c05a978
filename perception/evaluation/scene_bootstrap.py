"""A confidence interval for a mean over mushrooms that resamples whole scenes.

The mushrooms of one bed share its soil, crowding and camera noise, so their errors are not
independent, and resampling mushrooms understates a mean's uncertainty: for the shipped axis CNN
on 50 beds with the camera model ±0.34° against ±0.44° resampling beds, on 300 beds ±0.14°
against ±0.19° (docs/results-perception.md). Resampling scenes with replacement (a
cluster bootstrap; Davison & Hinkley, *Bootstrap Methods and their Application*, 1997, §3.8)
keeps that correlation. The statistic is the pooled mean — the sum of the resampled scenes'
errors over their count — the number `eval-pipeline` reports.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from perception.errors import PerceptionConfigError


def scene_bootstrap_interval(values: np.ndarray, scenes: np.ndarray, confidence: float = 0.95,
                             resamples: int = 2000, seed: int = 0) -> tuple[float, float] | None:
    """Percentile interval ``(low, high)`` of the mean of ``values (N,)`` with whole scenes
    resampled; ``scenes (N,)`` labels each value's scene (any hashable-as-array labels, e.g. ints
    or strings). ``None`` when the values come from fewer than two scenes (no spread to resample).

    Raises:
        PerceptionConfigError: lengths differ, a value is not finite, ``confidence`` is outside
            (0, 1) or ``resamples`` < 1 (the field is named).
    """
    values = np.asarray(values, dtype=np.float64)
    scenes = np.asarray(scenes)
    if values.ndim != 1 or scenes.shape != values.shape:
        raise PerceptionConfigError("scenes", f"needs one label per value: values {values.shape}, scenes {scenes.shape}")
    if not np.all(np.isfinite(values)):
        raise PerceptionConfigError("values", "must all be finite")
    if not isinstance(confidence, (int, float)) or not 0.0 < confidence < 1.0:
        raise PerceptionConfigError("confidence", f"must be in (0, 1), got {confidence!r}")
    if not isinstance(resamples, int) or isinstance(resamples, bool) or resamples < 1:
        raise PerceptionConfigError("resamples", f"must be an int >= 1, got {resamples!r}")
    labels, index = np.unique(scenes, return_inverse=True)
    if len(labels) < 2:
        return None
    sums = np.bincount(index, weights=values)
    counts = np.bincount(index).astype(np.float64)
    result = stats.bootstrap((sums, counts), lambda s, n, axis: s.sum(axis) / n.sum(axis), paired=True,
                             vectorized=True, n_resamples=resamples, confidence_level=confidence,
                             method="percentile", random_state=np.random.default_rng(seed))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


__all__ = ["scene_bootstrap_interval"]
