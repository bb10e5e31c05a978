"""Depth back-projection, filtering, sampling, normalisation and the no-estimate rule."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from generator.camera import Intrinsics as CameraIntrinsics
from perception.errors import DegenerateCloud, NoEstimate, PerceptionConfigError
from perception.pointcloud import (
    MIN_POINTS,
    MIN_SPREAD_M,
    Pinhole,
    depth_to_points,
    farthest_point_indices,
    normalize_points,
    pinhole_intrinsics,
    prepare_cloud,
    sample_points,
)

K = Pinhole(fx=400.0, fy=380.0, cx=32.0, cy=24.0)


def test_back_projection_follows_opencv_pinhole() -> None:
    depth = np.zeros((48, 64))
    depth[10, 50] = 0.5  # pixel right of and above the principal point
    pts, _ = depth_to_points(depth, K)
    assert pts.shape == (1, 3)
    np.testing.assert_allclose(pts[0], [(50 - 32) * 0.5 / 400, (10 - 24) * 0.5 / 380, 0.5], rtol=1e-6)
    # Reprojection gives the pixel back.
    u = K.fx * pts[0, 0] / pts[0, 2] + K.cx
    v = K.fy * pts[0, 1] / pts[0, 2] + K.cy
    assert (u, v) == pytest.approx((50, 10))


def test_invalid_depths_and_mask_are_filtered() -> None:
    depth = np.full((4, 5), 0.4)
    depth[0, 0], depth[0, 1], depth[0, 2], depth[0, 3] = np.nan, np.inf, 0.0, -1.0
    mask = np.ones((4, 5), bool)
    mask[3] = False
    rgb = np.full((4, 5, 3), 255, np.uint8)
    pts, cols = depth_to_points(depth, K, mask, rgb)
    assert len(pts) == 20 - 4 - 5  # 4 invalid depths in row 0, row 3 (5 pixels) masked out
    assert np.isfinite(pts).all() and (pts[:, 2] == np.float32(0.4)).all()
    np.testing.assert_allclose(cols, 1.0)
    with pytest.raises(ValueError, match="mask"):
        depth_to_points(depth, K, np.ones((3, 3), bool))


def test_nan_points_filtered_before_estimation() -> None:
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(100, 3)).astype(np.float32)
    pts[::3] = np.nan
    c = prepare_cloud(pts, 64, rng)
    assert np.isfinite(c.points).all() and c.num_valid == 66
    assert np.sqrt((c.points**2).sum(1)).max() <= 1.0 + 1e-5


def test_too_few_points_or_empty_mask_is_no_estimate() -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(NoEstimate) as info:
        prepare_cloud(np.ones((MIN_POINTS - 1, 3)), 64, rng)
    assert info.value.num_points == MIN_POINTS - 1
    depth = np.full((8, 8), 0.4)
    pts, _ = depth_to_points(depth, K, np.zeros((8, 8), bool))
    assert pts.shape == (0, 3)
    with pytest.raises(NoEstimate):
        prepare_cloud(pts, 64, rng)
    all_nan = np.full((50, 3), np.nan)
    with pytest.raises(NoEstimate):
        prepare_cloud(all_nan, 64, rng)


def test_sampling_sizes_and_fps_coverage() -> None:
    rng = np.random.default_rng(1)
    pts = rng.uniform(-1, 1, size=(500, 3))
    for n in (64, 500, 800):
        s, _ = sample_points(pts, n, rng)
        assert s.shape == (n, 3)
    few, _ = sample_points(pts[:20], 64, rng)
    assert len(np.unique(few, axis=0)) == 20  # every point used before any repeat
    idx = farthest_point_indices(pts, 32)
    assert len(set(idx.tolist())) == 32
    # FPS spreads out more than random sampling: larger minimum pairwise distance.
    def min_gap(q):
        d = np.linalg.norm(q[:, None] - q[None], axis=-1)
        return d[~np.eye(len(q), dtype=bool)].min()
    assert min_gap(pts[idx]) > min_gap(pts[rng.choice(500, 32, replace=False)])
    # Order independence of the FPS set.
    perm = rng.permutation(500)
    assert set(perm[farthest_point_indices(pts[perm], 32)].tolist()) == set(idx.tolist())


def test_normalise_round_trip() -> None:
    pts = np.random.default_rng(2).normal(0.3, 0.01, size=(200, 3))
    n, c, s = normalize_points(pts)
    assert np.sqrt((n**2).sum(1)).max() == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(n * s + c, pts, atol=1e-6)


def test_intrinsics_validation_names_field() -> None:
    with pytest.raises(PerceptionConfigError, match="fy"):
        Pinhole(400.0, -1.0, 0.0, 0.0)


def test_a_3x3_camera_matrix_is_accepted_as_intrinsics() -> None:
    depth = np.random.default_rng(3).uniform(0.3, 0.5, (48, 64))
    np.testing.assert_array_equal(depth_to_points(depth, K.matrix())[0], depth_to_points(depth, K)[0])
    assert pinhole_intrinsics(K.matrix().tolist()) == K
    assert pinhole_intrinsics(CameraIntrinsics(64, 48, 400.0, 380.0, 32.0, 24.0)) == K
    for bad in (np.eye(4), np.array([[400.0, 1.0, 32.0], [0.0, 380.0, 24.0], [0.0, 0.0, 1.0]]), "K", None):
        with pytest.raises(PerceptionConfigError, match="intrinsics"):
            depth_to_points(depth, bad)


_FIELDS = ("fx", "fy", "cx", "cy")
_BAD_FOCAL = st.one_of(st.sampled_from([float("nan"), float("inf"), -float("inf"), 0.0]),
                       st.floats(max_value=0.0, allow_nan=False))
_NOT_FINITE = st.sampled_from([float("nan"), float("inf"), -float("inf")])


@given(st.sampled_from(_FIELDS).flatmap(lambda f: st.tuples(st.just(f), _BAD_FOCAL if f in ("fx", "fy") else _NOT_FINITE)),
       st.sampled_from(["camera", "matrix"]))
def test_intrinsics_that_are_not_finite_or_not_positive_are_named(field_and_value, given_as) -> None:
    # fx = NaN or 0 used to turn every point into NaN: "too few valid points", not a word on fx.
    field, value = field_and_value
    values = dict(zip(_FIELDS, (400.0, 380.0, 32.0, 24.0)), **{field: value})
    camera = CameraIntrinsics(64, 48, **values)
    with pytest.raises(PerceptionConfigError) as info:
        depth_to_points(np.full((48, 64), 0.4), camera if given_as == "camera" else camera.matrix)
    assert info.value.field == field


@given(st.integers(MIN_POINTS, 600), st.floats(-0.1, 0.1), st.floats(0.1, 1.0),
       st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(lambda d: np.linalg.norm(d) > 0.1),
       st.floats(0.0, 0.1))
def test_points_at_one_place_or_on_one_line_are_degenerate(n, x, z, direction, length) -> None:
    # 500 identical or collinear points gave a confident rotation.
    t = np.linspace(-0.5, 0.5, n)[:, None]
    line = np.array([x, 0.0, z]) + t * length * np.asarray(direction) / np.linalg.norm(direction)
    with pytest.raises(DegenerateCloud) as info:
        prepare_cloud(line, 64, np.random.default_rng(0))
    assert info.value.num_points == n and info.value.spread_m < MIN_SPREAD_M
    assert isinstance(info.value, NoEstimate) and "degenerate" in str(info.value)


def test_a_thin_but_two_dimensional_cloud_is_not_degenerate() -> None:
    rng = np.random.default_rng(4)
    strip = np.column_stack((rng.uniform(-0.02, 0.02, 200), rng.uniform(-0.001, 0.001, 200), np.full(200, 0.4)))
    assert prepare_cloud(strip, 64, rng).num_valid == 200


def test_an_unknown_sampling_method_is_named_with_the_choices() -> None:
    rng = np.random.default_rng(5)
    pts = rng.normal(size=(100, 3))
    for n in (64, 200):  # with enough points "bogus" quietly ran farthest-point sampling
        with pytest.raises(PerceptionConfigError, match=r"method: must be one of \('random', 'fps'\), got 'bogus'"):
            sample_points(pts, n, rng, "bogus")
