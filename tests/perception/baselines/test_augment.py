"""Training-time augmentation: the occluder bite (``occlude_points``) and its configuration."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from perception.baselines.point_transformer.augment import AugmentConfig, occlude_points
from perception.baselines.point_transformer.data import PointCloudPoseDataset, PointCloudSample
from perception.errors import PerceptionConfigError
from perception.pointcloud import MIN_POINTS


def _dome(n: int = 2000, seed: int = 0) -> np.ndarray:
    """A 4 cm cap seen from 40 cm: camera-frame points (m), z forward."""
    u = np.random.default_rng(seed).uniform(-1, 1, (n, 2))
    u = u[(u**2).sum(1) < 1]
    return np.c_[0.02 * u, 0.4 - 0.01 * (1 - (u**2).sum(1))]


def _image_plane(p: np.ndarray) -> np.ndarray:
    return p[:, :2] / p[:, 2:3]


def test_the_bite_hides_the_asked_share_from_one_side():
    pts = _dome()
    kept, _ = occlude_points(pts, 0.4, np.random.default_rng(1))
    assert len(kept) == len(pts) - round(0.4 * len(pts))
    # what is kept is a subset, and the hidden part lies on one side: the kept centroid moves away from it
    assert {tuple(p) for p in kept} <= {tuple(p) for p in pts}
    hidden = np.array(sorted({tuple(p) for p in pts} - {tuple(p) for p in kept}))
    shift = _image_plane(kept).mean(0) - _image_plane(pts).mean(0)
    towards_hidden = _image_plane(hidden).mean(0) - _image_plane(pts).mean(0)
    assert shift @ towards_hidden < 0
    # one bite: every hidden point is nearer the hidden part's centre than the nearest kept point is
    c = _image_plane(hidden).mean(0)
    assert np.linalg.norm(_image_plane(kept) - c, axis=1).min() > 0.5 * np.linalg.norm(_image_plane(hidden) - c, axis=1).max()


def test_the_bite_is_seeded_and_cuts_colours_alike():
    pts = _dome()
    colors = np.random.default_rng(2).uniform(0, 1, pts.shape).astype(np.float32)
    a = occlude_points(pts, 0.3, np.random.default_rng(5), colors)
    b = occlude_points(pts, 0.3, np.random.default_rng(5), colors)
    np.testing.assert_array_equal(a[0], b[0])
    index = {tuple(p): i for i, p in enumerate(pts)}
    np.testing.assert_array_equal(a[1], colors[[index[tuple(p)] for p in a[0]]])


def test_non_finite_points_go_and_a_cloud_too_small_to_bite_is_kept_whole():
    pts = _dome()
    pts[:10] = np.nan
    kept, _ = occlude_points(pts, 0.2, np.random.default_rng(0))
    assert np.isfinite(kept).all()
    small = _dome()[: MIN_POINTS + 2]
    same, _ = occlude_points(small, 0.5, np.random.default_rng(0))
    assert same is small


def test_the_dataset_bites_only_when_asked_and_keeps_other_runs_streams():
    sample = PointCloudSample(points=_dome(), rotation=np.eye(3))
    plain = PointCloudPoseDataset([sample], num_points=256, augment=AugmentConfig(), seed=3)[0][0]
    off = PointCloudPoseDataset([sample], num_points=256, augment=AugmentConfig(occlusion_prob=0.0), seed=3)[0][0]
    bitten = PointCloudPoseDataset([sample], num_points=256, augment=AugmentConfig(occlusion_prob=1.0), seed=3)[0][0]
    assert np.array_equal(plain.numpy(), off.numpy())
    assert not np.array_equal(plain.numpy(), bitten.numpy()) and bitten.shape == plain.shape


@settings(max_examples=50, deadline=None)
@given(prob=st.one_of(st.floats(-1, 2), st.just(float("nan"))),
       lo=st.one_of(st.floats(-0.5, 1.5), st.just(float("nan"))), hi=st.floats(-0.5, 1.5))
def test_occlusion_settings_out_of_range_name_their_field(prob, lo, hi):
    ok_prob = 0 <= prob <= 1
    ok_fraction = 0 < lo <= hi < 1
    if ok_prob and ok_fraction:
        AugmentConfig(occlusion_prob=prob, occlusion_fraction=(lo, hi))
        return
    with pytest.raises(PerceptionConfigError, match="occlusion_prob" if not ok_prob else "occlusion_fraction"):
        AugmentConfig(occlusion_prob=prob, occlusion_fraction=(lo, hi))
