"""The shipped weights through ``PoseEstimator`` on rendered mushrooms, and no-estimate cases."""

from __future__ import annotations

import numpy as np
import pytest

from perception.baselines.point_transformer.estimator import (
    PoseEstimator,
    default_weights_path,
    turn_to_camera,
)
from perception.baselines.point_transformer.synthetic_views import (
    ViewConfig,
    default_models,
    generate_samples,
)
from perception.errors import DegenerateCloud, NoEstimate, PerceptionConfigError, PipelineInputError
from perception.pointcloud import depth_to_points

#: Stated tolerance: mean stem-axis error of the shipped network (8 test-time views, the
#: default) on 40 views of all 14 library models, 20° tilt σ: measured 3.0° (4.7° with one
#: view, 2.9° with the upright pass). perception/weights/README.md reports 1.8° / 2.5° (training
#: / held-out models) on 500 views each; always guessing "upright" gives ~25°.
AXIS_TOLERANCE_DEG = 5.0


@pytest.fixture(scope="module")
def estimator() -> PoseEstimator:
    assert default_weights_path().stat().st_size < 3 * 2**20  # package data stays small
    return PoseEstimator.from_pretrained(seed=0)


def _axis_err_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def test_shipped_weights_estimate_the_stem_axis(estimator: PoseEstimator) -> None:
    samples = generate_samples(40, seed=424242, models=default_models(), config=ViewConfig(surface_samples=20000))
    ests = estimator.estimate_batch([s.points for s in samples])
    errs = [_axis_err_deg(e.stem_axis, s.rotation[:, 2]) for e, s in zip(ests, samples, strict=True)]
    upright = [_axis_err_deg(np.array([0.0, 0.0, -1.0]), s.rotation[:, 2]) for s in samples]
    assert np.mean(errs) < AXIS_TOLERANCE_DEG
    assert np.mean(errs) < 0.7 * np.mean(upright)  # better than always guessing "upright"
    for e, s in zip(ests, samples, strict=True):
        R = e.rotation
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-4) and np.linalg.det(R) == pytest.approx(1, abs=1e-4)
        np.testing.assert_allclose(e.centre, s.points.mean(0), atol=1e-5)
        assert e.num_points == len(s.points)


def test_nan_depth_is_filtered_and_single_estimate_matches(estimator: PoseEstimator) -> None:
    s = generate_samples(1, seed=5, models=default_models(model_ids=(6,)))[0]
    pts = s.points.copy()
    pts[::7] = np.nan
    e = estimator.estimate(pts)
    assert np.isfinite(e.rotation).all() and np.isfinite(e.centre).all()
    assert e.num_points == int(np.isfinite(pts).all(1).sum())


def test_too_few_points_gives_no_estimate(estimator: PoseEstimator) -> None:
    depth = np.full((20, 20), 0.4)
    depth[5:8, 5:8] = np.nan
    mask = np.zeros((20, 20), bool)
    mask[4:8, 4:8] = True  # 16 pixels, 9 of them NaN → 7 valid points
    pts, _ = depth_to_points(depth, type("K", (), {"fx": 400.0, "fy": 400.0, "cx": 10.0, "cy": 10.0})(), mask)
    assert len(pts) == 7
    with pytest.raises(NoEstimate) as info:
        estimator.estimate(pts)
    assert info.value.num_points == 7
    assert estimator.estimate_or_none(pts) is None
    assert estimator.estimate_or_none(np.zeros((0, 3))) is None


def test_identical_or_collinear_points_give_no_estimate(estimator: PoseEstimator) -> None:
    # Both gave a "confident" rotation (a stem axis straight at the camera).
    same = np.tile([0.01, 0.02, 0.4], (500, 1))
    line = np.column_stack((np.linspace(-0.02, 0.02, 500), np.zeros(500), np.full(500, 0.4)))
    for cloud in (same, line):
        with pytest.raises(DegenerateCloud, match="degenerate cloud: 500 points"):
            estimator.estimate(cloud)
        assert estimator.estimate_or_none(cloud) is None


def test_clouds_in_millimetres_are_refused(estimator: PoseEstimator) -> None:
    # A cloud in millimetres got an estimate with its centre in millimetres.
    s = generate_samples(1, seed=5, models=default_models(model_ids=(6,)))[0]
    with pytest.raises(PipelineInputError, match=r"clouds\[1\] z: median 3\d\d is not a plausible distance in metres"):
        estimator.estimate_batch([s.points, s.points * 1000.0])


def test_an_unknown_sampling_method_is_refused(estimator: PoseEstimator) -> None:
    # "bogus" quietly ran farthest-point sampling on clouds larger than the network's input.
    with pytest.raises(PerceptionConfigError, match=r"sampling: must be one of \('random', 'fps'\)"):
        PoseEstimator(estimator.model, sampling="bogus")


@pytest.mark.parametrize("upright_pass", [False, True])
def test_test_time_views_are_turns_about_the_optical_axis(upright_pass: bool) -> None:
    # With FPS sampling every pass reads the same points, so turning the cloud a quarter turn
    # about the optical axis only permutes the 4 passes: the averaged estimate turns with it.
    # The upright pass's turn commutes with the quarter turn, so that holds for it too.
    est = PoseEstimator.from_pretrained(sampling="fps", views=4, upright_pass=upright_pass)
    s = generate_samples(3, seed=11, models=default_models(model_ids=(2,)))
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    plain = est.estimate_batch([x.points for x in s])
    turned = est.estimate_batch([x.points @ quarter.T for x in s])
    for a, b in zip(plain, turned, strict=True):
        np.testing.assert_allclose(b.rotation, quarter @ a.rotation, atol=2e-3)
        assert np.allclose(a.rotation.T @ a.rotation, np.eye(3), atol=1e-9) and np.linalg.det(a.rotation) > 0
    one = PoseEstimator.from_pretrained(sampling="fps", views=1).estimate(s[0].points)
    assert np.degrees(np.arccos(np.clip(one.stem_axis @ plain[0].stem_axis, -1, 1))) < 10.0
    with pytest.raises(PerceptionConfigError, match="views"):
        PoseEstimator.from_pretrained(views=0)


@pytest.mark.slow  # the baseline network on 40 rendered views: about a minute on 2 cores
def test_upright_pass_estimates_the_stem_axis(estimator: PoseEstimator) -> None:
    samples = generate_samples(40, seed=424242, models=default_models(), config=ViewConfig(surface_samples=20000))
    upright = PoseEstimator(estimator.model, upright_pass=True, seed=0).estimate_batch([s.points for s in samples])
    errs = [_axis_err_deg(e.stem_axis, s.rotation[:, 2]) for e, s in zip(upright, samples, strict=True)]
    assert np.mean(errs) < AXIS_TOLERANCE_DEG


def test_turn_to_camera_takes_the_axis_to_minus_z() -> None:
    axes = np.random.default_rng(0).normal(size=(20, 3))
    axes[0], axes[1] = (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)  # straight away from / at the camera
    Q = turn_to_camera(axes)
    unit = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", Q, unit), np.tile([0.0, 0.0, -1.0], (20, 1)), atol=1e-12)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", Q, Q), np.tile(np.eye(3), (20, 1, 1)), atol=1e-12)
    assert np.allclose(np.linalg.det(Q), 1.0)
    np.testing.assert_allclose(Q[1], np.eye(3))
    # The shortest turn leaves the direction perpendicular to both axes where it is.
    perp = np.cross(unit[5], [0.0, 0.0, -1.0])
    np.testing.assert_allclose(Q[5] @ perp, perp, atol=1e-12)


def test_workers_split_a_batch_without_changing_it(estimator: PoseEstimator) -> None:
    import torch

    x = torch.rand(9, estimator.config.num_points, 3) * 2 - 1
    split = PoseEstimator(estimator.model, workers=2)
    torch.testing.assert_close(split.infer(x), estimator.infer(x), atol=1e-6, rtol=0)
    with pytest.raises(PerceptionConfigError, match="workers"):
        PoseEstimator(estimator.model, workers=True)
