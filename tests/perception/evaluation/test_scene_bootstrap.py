"""The scene-resampling interval of a mean over mushrooms (``scene_bootstrap``)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from perception.errors import PerceptionConfigError
from perception.evaluation.eval_pipeline import PipelineReport
from perception.evaluation.scene_bootstrap import scene_bootstrap_interval


def _beds(rng, num_scenes, per_scene, scene_sd, mushroom_sd, mean=6.0):
    """Errors with a per-scene offset (shared soil and noise) plus per-mushroom scatter."""
    offsets = rng.normal(0.0, scene_sd, num_scenes)
    values = np.concatenate([mean + o + rng.normal(0.0, mushroom_sd, per_scene) for o in offsets])
    return values, np.repeat(np.arange(num_scenes), per_scene)


def test_the_interval_covers_the_true_mean_about_95_times_in_100():
    rng = np.random.default_rng(1)
    covered = per_mushroom = 0
    for trial in range(200):
        values, scenes = _beds(rng, 40, 30, scene_sd=0.8, mushroom_sd=4.0)
        low, high = scene_bootstrap_interval(values, scenes, resamples=1000, seed=trial)
        covered += low <= 6.0 <= high
        low, high = scene_bootstrap_interval(values, np.arange(len(values)), resamples=1000, seed=trial)
        per_mushroom += low <= 6.0 <= high
    # Binomial(200, 0.95) lies in [181, 197] with 99.9 % probability (the percentile interval of
    # 40 clusters runs a little narrow). Treating each mushroom as its own scene ignores the shared
    # offset and covers ≈ 80 % (its standard error is 1.5 times too small here).
    assert 178 <= covered <= 198
    assert per_mushroom <= 175


def test_copying_each_mushroom_within_its_scene_leaves_the_interval_alone():
    # Scenes are the independent draws: doubling every scene's mushrooms adds no information,
    # where a per-mushroom bootstrap would narrow by a factor sqrt(2).
    values, scenes = _beds(np.random.default_rng(2), 30, 20, scene_sd=1.0, mushroom_sd=3.0)
    once = scene_bootstrap_interval(values, scenes, seed=5)
    twice = scene_bootstrap_interval(np.repeat(values, 2), np.repeat(scenes, 2), seed=5)
    assert twice == pytest.approx(once, abs=1e-9)


def test_it_holds_the_pooled_mean_is_seeded_and_collapses_without_spread():
    values, scenes = _beds(np.random.default_rng(3), 25, 10, scene_sd=1.0, mushroom_sd=2.0)
    low, high = scene_bootstrap_interval(values, scenes, seed=0)
    assert low < values.mean() < high
    assert scene_bootstrap_interval(values, scenes, seed=0) == (low, high)
    assert scene_bootstrap_interval(values, scenes, seed=1) != (low, high)
    same = scene_bootstrap_interval(np.full(40, 4.5), np.repeat(np.arange(8), 5))
    assert same == pytest.approx((4.5, 4.5))


def test_one_scene_has_no_interval():
    assert scene_bootstrap_interval(np.array([1.0, 2.0, 3.0]), np.zeros(3, int)) is None


@given(confidence=st.one_of(st.floats(max_value=0.0), st.floats(min_value=1.0), st.just(float("nan"))))
def test_confidence_outside_0_1_is_refused_by_name(confidence):
    with pytest.raises(PerceptionConfigError, match="confidence"):
        scene_bootstrap_interval(np.arange(4.0), np.arange(4), confidence=confidence)


@given(resamples=st.one_of(st.integers(max_value=0), st.just(True), st.floats(allow_nan=False)))
def test_resamples_must_be_a_positive_int(resamples):
    with pytest.raises(PerceptionConfigError, match="resamples"):
        scene_bootstrap_interval(np.arange(4.0), np.arange(4), resamples=resamples)


def test_bad_values_and_labels_are_named():
    with pytest.raises(PerceptionConfigError, match="scenes"):
        scene_bootstrap_interval(np.arange(4.0), np.arange(3))
    with pytest.raises(PerceptionConfigError, match="values"):
        scene_bootstrap_interval(np.array([1.0, np.nan]), np.arange(2))


def _report(dataset, errors):
    rows = [{"dataset": dataset, "scene_id": 0, "matched": True, "axis_error_deg": e, "geodesic_error_deg": e,
             "cap_top_error_mm": e, "cap_top_lateral_error_mm": e, "cap_diameter_mm": 40.0, "tilt_deg": 10.0,
             "visible_fraction": 1.0} for e in errors]
    return PipelineReport(scenes=1, estimates=len(errors), seconds=1.0, rows=rows)


def test_pooled_reports_keep_scenes_of_different_datasets_apart():
    a, b = _report("beds_a", [2.0, 4.0]), _report("beds_b", [6.0, 8.0])
    assert a.summary()["axis_error_deg"]["mean_ci95"] is None  # one scene each
    pooled = PipelineReport.pooled([a, b])
    s = pooled.summary()
    assert (s["scenes"], s["ground_truth"], s["estimates"]) == (2, 4, 4)
    assert s["axis_error_deg"]["mean"] == pytest.approx(5.0)
    low, high = s["axis_error_deg"]["mean_ci95"]  # two scenes (both scene_id 0): means 3 and 7
    assert low == pytest.approx(3.0) and high == pytest.approx(7.0)
    assert "3.00–7.00" in pooled.markdown()
