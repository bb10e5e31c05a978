import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from generator.camera import project
from perception.baselines.point_transformer.depth_smoothing import smooth_depth_in_mask
from perception.baselines.point_transformer.estimator import PoseEstimator
from perception.baselines.point_transformer.pose_net import PoseNet, PoseNetConfig
from perception.detection.detector import Detection, detections_from_labels
from perception.errors import PerceptionConfigError
from perception.evaluation.eval_pipeline import GroundTruthMushroom, match
from perception.pipeline import (
    MushroomEstimate,
    PipelineInputError,
    PosePipeline,
    above_soil,
    estimate_cap_top,
    within_depth_of_core,
)
from perception.pointcloud import MIN_POINTS, depth_to_points


@pytest.fixture(scope="module")
def frame_and_scene(render_bed):
    scene, frame = render_bed(12, 4, 320, 240)
    return frame, scene


@pytest.fixture(scope="module")
def pipeline():
    # A small untrained network: these tests check plumbing and frames, not accuracy.
    net = PoseNet(PoseNetConfig(backbone="pointnet", num_points=128, hidden=16))
    return PosePipeline(PoseEstimator(net))  # the shipped detector, loaded only if a test needs it


def test_oracle_detections_follow_labels(frame_and_scene):
    frame, scene = frame_and_scene
    detections = detections_from_labels(frame.labels_mushroom)
    visible = {int(v) - 1 for v in np.unique(frame.labels_mushroom) if v}
    assert {d.instance_id for d in detections} == visible
    for d in detections:
        x0, y0, x1, y1 = d.box
        assert d.mask[y0:y1 + 1, x0:x1 + 1].sum() == d.area
    with pytest.raises(ValueError, match="labels"):
        detections_from_labels(np.zeros((4, 4), float))


def test_one_estimate_per_visible_mushroom_and_frames_agree(frame_and_scene, pipeline):
    frame, scene = frame_and_scene
    detections = detections_from_labels(frame.labels_cap)
    estimates = pipeline(frame.rgb, frame.depth, frame.intrinsics, frame.world_from_camera, detections)
    big_enough = [d for d in detections if d.area >= 40]  # well above 16 points after erosion
    assert len(estimates) >= len(big_enough) > 3
    for est in estimates:
        R = est.rotation_world
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-5) and np.isclose(np.linalg.det(R), 1, atol=1e-5)
        assert np.all(np.isfinite(est.cap_top_world))
        # The world-frame centre projects back onto the mushroom's own mask.
        u, v, _ = project(est.centre_world[None], frame.world_from_camera, frame.intrinsics)[0]
        window = est.detection.mask[int(round(v)) - 2:int(round(v)) + 3, int(round(u)) - 2:int(round(u)) + 3]
        assert window.any()
        # ... and lies near that mushroom's true cap (within a cap diameter).
        truth = scene.instances[est.detection.instance_id]
        assert np.linalg.norm(est.centre_world - truth.cap_obb.center) < truth.cap_diameter


def test_an_axis_model_gives_each_estimate_its_axis_and_the_cap_top_follows_it(frame_and_scene):
    from perception.pose.axis_cnn import AxisCNN, AxisCNNEstimator

    frame, scene = frame_and_scene
    axis_model = AxisCNNEstimator(AxisCNN())  # untrained: "along the ray, towards the camera"
    detections = detections_from_labels(frame.labels_mushroom)
    estimates = PosePipeline(None, None, axis_model=axis_model)(frame.rgb, frame.depth, frame.intrinsics,
                                                                frame.world_from_camera, detections)
    assert len(estimates) >= 8
    axes = axis_model.estimate_axes(frame.rgb, frame.depth, [e.detection.mask for e in estimates], frame.intrinsics)
    for est, axis in zip(estimates, axes):
        assert np.allclose(est.rotation_cam[:, 2], axis, atol=1e-9)
        assert np.allclose(est.rotation_cam.T @ est.rotation_cam, np.eye(3), atol=1e-9)
        assert np.allclose(est.rotation_world, frame.world_from_camera[:3, :3] @ est.rotation_cam)
        points, _ = depth_to_points(frame.depth, frame.intrinsics, est.detection.mask)
        assert np.allclose(est.centre_cam, points.mean(0)) and est.num_points == len(points)
        assert np.allclose(est.cap_top_cam, estimate_cap_top(points.astype(np.float64), axis))


def test_a_pipeline_without_a_pose_estimator_or_axis_model_refuses_to_estimate(frame_and_scene):
    frame, _ = frame_and_scene
    with pytest.raises(PerceptionConfigError, match="estimator"):
        PosePipeline(None, None)(frame.rgb, frame.depth, frame.intrinsics, frame.world_from_camera,
                                 detections_from_labels(frame.labels_mushroom))


def test_no_detections_and_tiny_masks_give_no_estimates(frame_and_scene, pipeline):
    frame, _ = frame_and_scene
    assert pipeline(frame.rgb, frame.depth, frame.intrinsics, frame.world_from_camera, []) == []
    tiny = np.zeros(frame.depth.shape, np.uint16)
    tiny[10:13, 10:13] = 1
    assert pipeline(frame.rgb, frame.depth, frame.intrinsics, frame.world_from_camera, detections_from_labels(tiny)) == []


def test_bad_inputs_are_named(frame_and_scene, pipeline):
    frame, _ = frame_and_scene
    args = (frame.rgb, frame.depth, frame.intrinsics, frame.world_from_camera, [])
    with pytest.raises(PipelineInputError, match="rgb"):
        pipeline(frame.rgb.astype(np.float32), *args[1:])
    with pytest.raises(PipelineInputError, match="unit"):
        pipeline(frame.rgb, frame.depth * 1000.0, *args[2:])
    with pytest.raises(PipelineInputError, match="float"):
        pipeline(frame.rgb, (frame.depth * 1000).astype(np.uint16), *args[2:])
    with pytest.raises(PipelineInputError, match="intrinsics"):
        pipeline(frame.rgb[:100], frame.depth[:100], *args[2:])
    with pytest.raises(PipelineInputError, match="world_from_camera"):
        pipeline(frame.rgb, frame.depth, frame.intrinsics, np.eye(3), [])
    with pytest.raises(ValueError, match="detector"):
        PosePipeline(pipeline.estimator, detector=None)(*args[:4])  # oracle mode: masks must be passed


def test_a_camera_matrix_works_as_intrinsics(frame_and_scene, pipeline):
    # A 3 x 3 K was an AttributeError ('numpy.ndarray' object has no attribute 'width').
    frame, _ = frame_and_scene
    detections = detections_from_labels(frame.labels_mushroom)
    args = (frame.rgb, frame.depth)
    with_k = pipeline(*args, frame.intrinsics.matrix, frame.world_from_camera, detections)
    plain = pipeline(*args, frame.intrinsics, frame.world_from_camera, detections)
    assert len(with_k) == len(plain) > 3
    for a, b in zip(with_k, plain):
        assert a.num_points == b.num_points
        np.testing.assert_allclose(a.centre_world, b.centre_world)


@pytest.mark.parametrize("fx", [float("nan"), 0.0, -380.0])
def test_a_bad_focal_length_is_named(frame_and_scene, pipeline, fx):
    # fx NaN or 0 gave NaN points and "no estimate: too few valid points".
    frame, _ = frame_and_scene
    bad = dataclasses.replace(frame.intrinsics, fx=fx)
    detections = detections_from_labels(frame.labels_mushroom)
    for intrinsics in (bad, bad.matrix):
        with pytest.raises(PerceptionConfigError, match="fx: must be"):
            pipeline(frame.rgb, frame.depth, intrinsics, frame.world_from_camera, detections)


def test_a_mask_whose_points_lie_on_a_line_gives_no_estimate(frame_and_scene, pipeline):
    # One row of pixels on a flat surface seen square on: collinear points, which the network
    # would turn into a confident rotation.
    frame, _ = frame_and_scene
    labels = np.zeros(frame.depth.shape, np.uint16)
    labels[100, 100:140] = 1
    flat = np.full(frame.depth.shape, 0.4, np.float32)
    assert pipeline(frame.rgb, flat, frame.intrinsics, frame.world_from_camera, detections_from_labels(labels)) == []


def test_above_soil_trims_a_mask_that_spills_onto_the_soil():
    depth = np.full((60, 80), 0.40, np.float32)  # soil 40 cm away
    yy, xx = np.mgrid[:60, :80]
    cap = (yy - 30) ** 2 + (xx - 40) ** 2 <= 10 ** 2
    depth[cap] = 0.37  # a cap 3 cm above the soil
    spilled = (yy - 30) ** 2 + (xx - 40) ** 2 <= 13 ** 2
    assert np.array_equal(above_soil(spilled, depth, 0.006), cap)
    assert np.array_equal(above_soil(cap, np.zeros_like(depth), 0.006), cap)  # no depth around: unchanged


def _dome_over_soil():
    """A cap of radius 10 px whose rim falls away 4 mm from its centre, 3 cm above the soil."""
    yy, xx = np.mgrid[:60, :80]
    r2 = (yy - 30) ** 2 + (xx - 40) ** 2
    depth = np.full((60, 80), 0.40, np.float32)
    cap = r2 <= 10 ** 2
    depth[cap] = 0.37 + 0.004 * r2[cap] / 100.0
    return depth, cap, r2


def test_within_depth_of_core_drops_the_soil_beyond_a_rim_and_keeps_the_rim():
    depth, cap, r2 = _dome_over_soil()
    spilled = r2 <= 12 ** 2  # two pixels over the rim
    assert np.array_equal(within_depth_of_core(spilled, depth, 0.008), cap)
    # A tolerance under the rim's own fall (1.4 mm over its last two pixels) cuts into the cap.
    assert np.array_equal(within_depth_of_core(cap, depth, 0.008), cap)
    tight = within_depth_of_core(cap, depth, 0.001)
    assert tight.sum() < cap.sum() and not (tight & ~cap).any()
    tiny = r2 <= 2 ** 2  # too small an interior to judge by: unchanged
    assert np.array_equal(within_depth_of_core(tiny, depth, 0.008), tiny)
    # A 2-px sliver of another cap, 12 px from this one's interior, has no interior of its own
    # to be judged by: it stays, whatever its depth.
    sliver = np.zeros_like(cap)
    sliver[20:40, 60:62] = True
    depth_with_sliver = depth.copy()
    depth_with_sliver[sliver] = 0.39
    assert np.array_equal(within_depth_of_core(cap | sliver, depth_with_sliver, 0.008), cap | sliver)
    # Spilled pixels without valid depth carry no points: kept alike, whether 0, NaN or inf.
    holes = depth.copy()
    holes[30, 51], holes[30, 29], holes[41, 40] = 0.0, np.nan, np.inf
    kept = within_depth_of_core(spilled, holes, 0.008)
    assert kept[30, 51] and kept[30, 29] and kept[41, 40]
    assert np.array_equal(kept & np.isfinite(holes) & (holes > 0), cap & np.isfinite(holes) & (holes > 0))


def test_the_pipeline_cuts_its_clouds_from_the_trimmed_masks():
    depth, cap, r2 = _dome_over_soil()
    spilled = r2 <= 12 ** 2
    whole = PosePipeline(None, detector=None)  # type: ignore[arg-type]
    assert np.array_equal(whole.trim_mask(spilled, depth), spilled)
    trimmed = PosePipeline(None, detector=None, edge_tolerance_m=0.008)  # type: ignore[arg-type]
    assert np.array_equal(trimmed.trim_mask(spilled, depth), cap)


def test_a_network_trained_on_smoothed_depth_is_fed_smoothed_depth(frame_and_scene, monkeypatch):
    frame, _ = frame_and_scene
    net = PoseNet(PoseNetConfig(backbone="pointnet", num_points=128, hidden=16, depth_smoothing_px=3.0))
    pipeline = PosePipeline(PoseEstimator(net), detector=None)
    detections = detections_from_labels(frame.labels_mushroom)
    seen = []
    estimate_batch = pipeline.estimator.estimate_batch
    monkeypatch.setattr(pipeline.estimator, "estimate_batch", lambda clouds, colours: seen.extend(clouds)
                        or estimate_batch(clouds, colours))
    estimates = pipeline(frame.rgb, frame.depth, frame.intrinsics, frame.world_from_camera, detections)
    assert len(seen) == len(estimates) > 3
    for est, cloud in zip(estimates, seen, strict=True):
        mask = est.detection.mask
        smoothed, _ = depth_to_points(smooth_depth_in_mask(frame.depth, mask, 3.0), frame.intrinsics, mask)
        raw, _ = depth_to_points(frame.depth, frame.intrinsics, mask)
        assert np.allclose(cloud, smoothed, atol=1e-6)
        assert len(raw) == len(cloud) and not np.allclose(cloud, raw, atol=1e-6)
    # An explicit 0 overrides the network's setting.
    raw_pipeline = PosePipeline(PoseEstimator(net), detector=None, depth_smoothing_px=0.0)
    mask = detections[0].mask
    assert raw_pipeline.cloud_pixels(mask, frame.depth)[1] is frame.depth


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.05))
def test_within_depth_of_core_only_removes_border_pixels(seed, tolerance):
    rng = np.random.default_rng(seed)
    depth = rng.uniform(0.3, 0.5, (40, 50)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.1] = 0.0  # invalid pixels
    mask = rng.random(depth.shape) < 0.7
    out = within_depth_of_core(mask, depth, tolerance)
    assert not (out & ~mask).any()
    import cv2

    core = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert (out[core] | ~mask[core]).all()
    # What it removes lies deeper than the tolerance below some interior pixel within 3 px.
    interior = np.where(core & (depth > 0), depth, 0.0).astype(np.float32)
    deepest = cv2.dilate(interior, np.ones((7, 7), np.uint8))
    removed = mask & ~out
    if np.count_nonzero(core & (depth > 0)) >= MIN_POINTS:
        assert (deepest[removed] > 0).all() and (depth[removed] > deepest[removed] + tolerance).all()
    else:
        assert not removed.any()


def test_cap_top_is_the_apex_of_a_dome_seen_from_one_side() -> None:
    # A spherical cap (radius 30 mm) about a tilted axis, keeping the points whose normals face
    # a camera off to one side: the centroid of what it sees is off the axis, the apex is not.
    rng = np.random.default_rng(0)
    axis = np.array([np.sin(0.3), 0.0, np.cos(0.3)])
    normals = rng.normal(size=(20000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals[normals @ axis > np.cos(0.9)]
    to_camera = np.array([-0.6, 0.3, 0.74])
    normals = normals[normals @ to_camera > 0.2]
    centre = np.array([0.1, -0.05, 0.3])
    points, apex = centre + 0.03 * normals, centre + 0.03 * axis
    off_axis = points.mean(0) - centre - ((points.mean(0) - centre) @ axis) * axis
    assert np.linalg.norm(off_axis) > 0.004  # the axis through the centroid misses by > 4 mm
    assert np.linalg.norm(estimate_cap_top(points, axis) - apex) < 0.001
    # A few stray points above the cap do not move it (the top is a high percentile, not the max).
    strays = apex + 0.01 * axis + rng.normal(0, 0.002, (10, 3))
    assert np.linalg.norm(estimate_cap_top(np.vstack([points, strays]), axis) - apex) < 0.0015


@pytest.mark.parametrize("seed", range(5))
def test_cap_top_of_a_dome_under_stereo_depth_noise_is_found_to_half_a_millimetre(seed: int) -> None:
    # A 25 mm dome tilted 17°, every point moved along the camera's z by the D405's noise at
    # 0.4 m (1.9 mm): the highest few points are the noisiest, the fitted dome averages them.
    rng = np.random.default_rng(seed)
    axis = np.array([np.sin(0.3), 0.0, np.cos(0.3)])
    normals = rng.normal(size=(6000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals[(normals @ axis > np.cos(1.2)) & (normals[:, 2] > 0.1)]
    centre = np.array([0.02, -0.01, 0.4])
    points, apex = centre + 0.025 * normals, centre + 0.025 * axis
    points[:, 2] += rng.normal(0.0, 0.0019, len(points))
    heights = points @ axis
    band = heights >= np.percentile(heights, 99) - 0.001
    highest = points[band].mean(0) + axis * (np.percentile(heights, 99) - heights[band].mean())
    assert np.linalg.norm(highest - apex) > 0.0012  # where the highest points are: millimetres off
    assert np.linalg.norm(estimate_cap_top(points, axis) - apex) < 0.0006


def test_cap_top_of_points_that_make_no_dome_is_the_top_band() -> None:
    # A bowl (curving up away from the axis) and a handful of points: no dome to fit.
    rng = np.random.default_rng(0)
    uv = rng.uniform(-0.02, 0.02, (400, 2))
    bowl = np.c_[uv, 10.0 * (uv**2).sum(1)]
    axis = np.array([0.0, 0.0, 1.0])
    top = estimate_cap_top(bowl, axis)
    heights = bowl[:, 2]
    assert np.isfinite(top).all()
    assert top[2] == pytest.approx(np.percentile(heights, 99))
    assert np.isfinite(estimate_cap_top(bowl[:5], axis)).all()


def test_match_splits_the_cap_top_error_along_and_across_the_stem():
    # A mushroom tilted 90° about x (stem along -y) and an estimate whose cap top is 3 mm along
    # the stem and 4 mm across it: 5 mm in all, 4 mm across.
    mask = np.zeros((8, 8), bool)
    mask[2:5, 2:5] = True
    rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    top = np.array([0.01, 0.02, 0.03])
    truth = GroundTruthMushroom(0, 0, mask, rot, top, 40.0, 90.0, 1.0)
    est_top = top + 0.003 * rot[:, 2] + np.array([0.004, 0.0, 0.0])
    est = MushroomEstimate(Detection(mask, (2, 2, 4, 4), 1.0, 0), rot, est_top, est_top, rot, est_top, est_top, 100)
    (row,) = match([est], [truth])
    assert row["matched"] and row["axis_error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert row["cap_top_error_mm"] == pytest.approx(5.0) and row["cap_top_lateral_error_mm"] == pytest.approx(4.0)


def test_eval_pipeline_names_how_its_clouds_are_cut(tmp_path, capsys):
    import argparse

    from perception.baselines.point_transformer.pose_net import save_checkpoint
    from perception.cli_detector import _pipeline

    path = tmp_path / "smoothed.pt"
    save_checkpoint(path, PoseNet(PoseNetConfig(backbone="pointnet", num_points=64, hidden=16, depth_smoothing_px=3.0)))
    args = argparse.Namespace(weights=str(path), detector="oracle", soil_margin_mm=0.0, edge_tolerance_mm=0.0,
                              score_threshold=None, pose_model="points")
    pipeline, oracle = _pipeline(args, [])  # no --data to check
    out = capsys.readouterr().out
    assert oracle and "clouds: depth smoothed in each mask, sigma 3 px (the network's setting)" in out
    depth, cap, _ = _dome_over_soil()
    assert np.array_equal(pipeline.cloud_pixels(cap, depth)[1], smooth_depth_in_mask(depth, cap, 3.0))
