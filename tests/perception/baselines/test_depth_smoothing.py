import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from generator.dataset.realism import correlated_unit_noise
from perception.baselines.point_transformer.depth_smoothing import smooth_depth_in_mask


def _dome(shape=(90, 120), radius=25):
    """A cap dome 35 mm below a camera 0.4 m over the soil (rim 4 mm below the apex), in pixels."""
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    r2 = (yy - shape[0] // 2) ** 2 + (xx - shape[1] // 2) ** 2
    depth = np.full(shape, 0.40, np.float32)
    cap = r2 <= radius**2
    depth[cap] = 0.365 + 0.004 * r2[cap] / radius**2
    return depth, cap


def test_smoothing_removes_most_of_a_stereo_cameras_correlated_noise_on_a_cap():
    depth, cap = _dome()
    rng = np.random.default_rng(0)
    # The camera model's noise: 1.9 mm (a D405 at 0.4 m) correlated over a 7-pixel window.
    noisy = depth + 0.0019 * correlated_unit_noise(depth.shape, 7, rng).astype(np.float32)
    smoothed = smooth_depth_in_mask(noisy, cap, 4.0)
    raw_error = np.sqrt(np.mean((noisy[cap] - depth[cap]) ** 2))
    smoothed_error = np.sqrt(np.mean((smoothed[cap] - depth[cap]) ** 2))
    assert 1.6e-3 < raw_error < 2.2e-3
    assert smoothed_error < 0.5 * raw_error
    # A noise-free dome keeps its shape: within 0.3 mm everywhere (the rim, a one-sided mean, most).
    assert np.abs(smooth_depth_in_mask(depth, cap, 4.0)[cap] - depth[cap]).max() < 3e-4


def test_no_depth_from_outside_the_mask_leaks_in():
    depth, cap = _dome()
    smoothed = smooth_depth_in_mask(depth, cap, 6.0)
    # The soil 35 mm below would pull the rim down by millimetres if it were averaged in.
    assert smoothed[cap].max() <= depth[cap].max() + 1e-6
    assert np.array_equal(smoothed[~cap], depth[~cap])


def test_pixels_a_mean_would_move_too_far_keep_their_own_depth():
    depth, cap = _dome()
    flying = (45, 60)
    depth[flying] = 0.385  # a flying pixel half way to the soil
    smoothed = smooth_depth_in_mask(depth, cap, 4.0, max_shift_m=0.006)
    assert smoothed[flying] == pytest.approx(0.385)
    moved = smooth_depth_in_mask(depth, cap, 4.0, max_shift_m=0.05)
    assert moved[flying] < 0.37


def test_invalid_pixels_stay_invalid_and_add_nothing():
    depth, cap = _dome()
    holes = depth.copy()
    holes[40:43, 55:58] = 0.0
    holes[50, 50], holes[50, 70] = np.nan, np.inf
    smoothed = smooth_depth_in_mask(holes, cap, 4.0)
    assert (smoothed[40:43, 55:58] == 0).all() and np.isnan(smoothed[50, 50]) and np.isinf(smoothed[50, 70])
    fine = cap & np.isfinite(holes) & (holes > 0)
    assert np.abs(smoothed[fine] - smooth_depth_in_mask(depth, cap, 4.0)[fine]).max() < 2e-4


def test_zero_sigma_and_empty_masks_change_nothing():
    depth, cap = _dome()
    assert np.array_equal(smooth_depth_in_mask(depth, cap, 0.0), depth)
    assert np.array_equal(smooth_depth_in_mask(depth, np.zeros_like(cap), 4.0), depth)


@pytest.mark.parametrize("sigma", [-1.0, float("nan"), float("inf")])
def test_a_bad_sigma_is_named(sigma):
    depth, cap = _dome()
    with pytest.raises(ValueError, match="sigma_px"):
        smooth_depth_in_mask(depth, cap, sigma)


def test_a_mask_of_another_shape_is_refused():
    depth, cap = _dome()
    with pytest.raises(ValueError, match="mask shape"):
        smooth_depth_in_mask(depth, cap[:-1], 4.0)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 8.0))
def test_only_valid_mask_pixels_change_and_never_beyond_the_shift_limit(seed, sigma):
    rng = np.random.default_rng(seed)
    depth = rng.uniform(0.3, 0.5, (30, 40)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.1] = 0.0
    mask = rng.random(depth.shape) < 0.5
    out = smooth_depth_in_mask(depth, mask, sigma, max_shift_m=0.01)
    changed = out != depth
    assert not (changed & ~(mask & (depth > 0))).any()
    assert (np.abs(out - depth) <= 0.01 + 1e-6).all()


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(1.5, 8.0), st.floats(-2e-3, 2e-3), st.floats(-2e-3, 2e-3))
def test_a_tilted_plane_is_left_as_it_is_rims_and_holes_alike(seed, sigma, slope_x, slope_y):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:30, :40]
    plane = (0.4 + slope_x * x + slope_y * y).astype(np.float32)  # up to 2 mm a pixel
    mask = np.zeros(plane.shape, bool)
    mask[3:27, 4:36] = True
    mask &= rng.random(plane.shape) > 0.2  # a fifth of it missing
    assert np.abs(smooth_depth_in_mask(plane, mask, sigma) - plane).max() < 2e-5
