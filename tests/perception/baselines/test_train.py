"""Synthetic views, the dataset format, and a short real training run."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from perception.baselines.point_transformer.data import (
    DatasetFormatError,
    PointCloudPoseDataset,
    PointCloudSample,
    load_samples,
    save_samples,
)
from perception.baselines.point_transformer.pose_net import PoseNet, PoseNetConfig
from perception.baselines.point_transformer.synthetic_views import (
    CAMERA_FROM_WORLD,
    ViewConfig,
    default_models,
    generate_samples,
    posed_mesh,
    render_view,
)
from perception.baselines.point_transformer.train import TrainConfig, evaluate, train
from perception.errors import PerceptionConfigError
from perception.pose.rotations import CHANCE_AXIS_DEG, CHANCE_GEODESIC_DEG

FAST_VIEWS = ViewConfig(tilt_std_deg=45.0, surface_samples=8000)


@pytest.fixture(scope="module")
def models():
    return default_models(model_ids=(0, 1))


def test_views_are_consistent_with_their_labels(models) -> None:
    rng = np.random.default_rng(0)
    cfg = ViewConfig(tilt_std_deg=0.0, depth_noise_std=0.0, xy_range=0.0)
    s = render_view(models[0], rng, cfg)
    R = s.rotation
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-5) and np.linalg.det(R) == pytest.approx(1.0, abs=1e-5)
    # Upright mushroom below the camera: stem axis points at the camera (camera −z), and the
    # highest points (cap top) are the nearest.
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-6)
    top = s.points[:, 2].min()
    assert 0.3 < top < 0.4
    # The cloud is about as wide as the cap.
    width = np.ptp(s.points[:, 0])
    assert width == pytest.approx(s.meta["cap_diameter"], rel=0.25)
    # Tilted: the observed points spread along the stem axis from the cap towards the soil,
    # so the cloud's extent along the axis is the visible height, and points lie "above" the
    # soil plane (negative camera z relative to the stem base).
    s2 = render_view(models[0], np.random.default_rng(3), ViewConfig(tilt_std_deg=30.0, depth_noise_std=0.0))
    assert len(s2.points) > 100 and np.isfinite(s2.points).all()
    base = np.diag([1.0, -1.0, -1.0]) @ (np.array(s2.meta["position_world"]) - [0, 0, 0.40])
    heights = (s2.points - base) @ s2.rotation[:, 2]
    assert heights.min() > -0.003
    assert heights.mean() > 0.3 * heights.max()


def test_a_views_metadata_poses_its_mesh_onto_its_points(models) -> None:
    import trimesh

    config = ViewConfig(tilt_std_deg=25.0, depth_noise_std=0.0)
    s = render_view(models[0], np.random.default_rng(5), config)
    assert len(s.meta["stretch"]) == 3
    mesh = posed_mesh(models[0], s.meta)
    origin = CAMERA_FROM_WORLD @ (np.array(s.meta["position_world"]) - [0, 0, config.camera_height])
    _, distance, _ = trimesh.proximity.closest_point(mesh, (s.points - origin) @ s.rotation)
    assert np.median(distance) < 5e-4  # on the surface but for the pixel grid's quantisation
    unstretched = models[0].mesh.copy()
    unstretched.apply_transform(np.diag([s.meta["scale"] * 1.2] * 3 + [1.0]))
    _, off, _ = trimesh.proximity.closest_point(unstretched, (s.points - origin) @ s.rotation)
    assert np.median(off) > 2 * np.median(distance)


def test_generation_is_deterministic(models) -> None:
    a = generate_samples(3, 7, models, FAST_VIEWS)
    b = generate_samples(3, 7, models, FAST_VIEWS)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.points, y.points) and np.array_equal(x.rotation, y.rotation)


def test_npz_round_trip_and_errors(tmp_path, models) -> None:
    samples = generate_samples(4, 1, models, FAST_VIEWS)
    path = tmp_path / "s.npz"
    save_samples(path, samples)
    back = load_samples(path)
    assert len(back) == 4
    for x, y in zip(samples, back, strict=True):
        assert np.array_equal(x.points, y.points) and np.array_equal(x.colors, y.colors)
        assert np.allclose(x.rotation, y.rotation) and x.meta == y.meta
    np.savez(tmp_path / "bad.npz", points=np.zeros((2, 3)))
    with pytest.raises(DatasetFormatError, match="offsets"):
        load_samples(tmp_path / "bad.npz")


def test_dataset_items_and_small_samples_dropped() -> None:
    rng = np.random.default_rng(0)
    good = PointCloudSample(rng.normal(size=(300, 3)).astype(np.float32), np.eye(3, dtype=np.float32))
    tiny = PointCloudSample(rng.normal(size=(5, 3)).astype(np.float32), np.eye(3, dtype=np.float32))
    ds = PointCloudPoseDataset([good, tiny], num_points=128)
    assert len(ds) == 1 and ds.num_dropped == 1
    x, R, i = ds[0]
    assert x.shape == (128, 3) and R.shape == (3, 3) and i == 0
    assert torch.equal(ds[0][0], x)  # reproducible per (seed, epoch, index)


@pytest.mark.slow  # trains the baseline network: about a minute on 2 cores
def test_short_training_beats_chance_and_the_upright_prior(tmp_path, models) -> None:
    """Point Transformer, 128 points, 20 epochs on 384 views (45° tilt σ) — about 20 s."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small tensors: one thread is faster and immune to oversubscription
    try:
        _short_training(tmp_path, models)
    finally:
        torch.set_num_threads(threads)


def _short_training(tmp_path, models) -> None:
    torch.manual_seed(0)
    train_s = generate_samples(384, 1, models, FAST_VIEWS)
    val_s = generate_samples(96, 2, models, FAST_VIEWS)
    net = PoseNetConfig(num_points=128)
    val = PointCloudPoseDataset(val_s, 128)
    _, before, *_ = evaluate(PoseNet(net), val)
    cfg = TrainConfig(epochs=20, lr=3e-3, loss="geodesic+axis", progress=False)
    model, rows = train(net, cfg, PointCloudPoseDataset(train_s, 128, augment=cfg.augment), val, tmp_path)
    _, after, *_ = evaluate(model, val)
    assert len(rows) == 20 and (tmp_path / "log.csv").exists() and (tmp_path / "best.pt").exists()
    # Untrained, the head predicts an upright mushroom: axis error ≈ the tilt spread (~55°).
    assert after.mean_axis_deg < 0.6 * before.mean_axis_deg
    assert after.mean_axis_deg < CHANCE_AXIS_DEG / 3
    assert after.mean_geodesic_deg < CHANCE_GEODESIC_DEG - 15


def test_a_rerun_resumes_from_the_last_checkpoint_and_other_settings_are_refused(tmp_path, models, capsys) -> None:
    from generator.run_folder import RunFolderError

    s = generate_samples(48, 3, models, FAST_VIEWS)
    net = PoseNetConfig(backbone="pointnet", num_points=64)
    ds = PointCloudPoseDataset(s[:32], 64)
    val = PointCloudPoseDataset(s[32:], 64)
    _, rows1 = train(net, TrainConfig(epochs=1, progress=False), ds, val, tmp_path)
    capsys.readouterr()
    _, rows2 = train(net, TrainConfig(epochs=3, progress=False), ds, val, tmp_path)  # the same settings, more epochs
    assert [r["epoch"] for r in rows2] == [1, 2, 3] and rows2[0] == rows1[0]
    assert f"resuming {tmp_path} from epoch 1 of 3" in capsys.readouterr().err
    for field, (n, cfg, data) in {"lr": (net, TrainConfig(epochs=3, lr=1e-3, progress=False), ds),
                                  "head": (PoseNetConfig(backbone="pointnet", head="6d_stem", num_points=64),
                                           TrainConfig(epochs=3, progress=False), ds),
                                  "train_data": (net, TrainConfig(epochs=3, progress=False),
                                                 PointCloudPoseDataset(s[:31], 64))}.items():
        with pytest.raises(RunFolderError, match=rf"other settings: {field} \("):
            train(n, cfg, data, val, tmp_path)
    _, rows3 = train(net, TrainConfig(epochs=1, lr=1e-3, progress=False), ds, val, tmp_path, overwrite=True)
    assert len(rows3) == 1


def test_init_fine_tunes_from_a_checkpoint(tmp_path, models) -> None:
    from perception.baselines.point_transformer.pose_net import load_checkpoint
    from perception.errors import CheckpointMismatchError

    s = generate_samples(48, 4, models, FAST_VIEWS)
    net = PoseNetConfig(backbone="pointnet", num_points=64)
    ds, val = PointCloudPoseDataset(s[:32], 64), PointCloudPoseDataset(s[32:], 64)
    train(net, TrainConfig(epochs=1, progress=False), ds, val, tmp_path / "a")
    init = tmp_path / "a" / "best.pt"
    start, _ = load_checkpoint(init)
    # With a negligible learning rate, the first epoch validates the checkpoint's own weights.
    tiny = TrainConfig(epochs=1, lr=1e-12, progress=False, augment=None)
    val_loss = evaluate(start, val, loss=tiny.loss)[0]
    model, rows = train(net, tiny, ds, val, tmp_path / "b", init=init)
    assert rows[0]["val_loss"] == pytest.approx(val_loss, rel=1e-5)
    for k, v in start.state_dict().items():
        assert torch.allclose(v, model.state_dict()[k], atol=1e-6), k
    _, scratch = train(net, tiny, ds, val, tmp_path / "c")
    assert scratch[0]["val_loss"] != pytest.approx(val_loss, rel=1e-5)
    with pytest.raises(CheckpointMismatchError):
        train(PoseNetConfig(backbone="pointnet", num_points=128), TrainConfig(epochs=1, progress=False),
              ds, val, tmp_path / "d", init=init)
    # Fine-tuning for smoothed depth starts from the same weights and saves the new input field.
    smoothed = PoseNetConfig(backbone="pointnet", num_points=64, depth_smoothing_px=4.0)
    model, rows = train(smoothed, tiny, ds, val, tmp_path / "e", init=init)
    assert rows[0]["val_loss"] == pytest.approx(val_loss, rel=1e-5)
    assert load_checkpoint(tmp_path / "e" / "best.pt")[0].config.depth_smoothing_px == 4.0


def test_cli_train_pose_init(tmp_path, models) -> None:
    from perception.cli_pose import main

    s = generate_samples(40, 5, models, FAST_VIEWS)
    save_samples(tmp_path / "tr.npz", s[:32])
    save_samples(tmp_path / "va.npz", s[32:])
    common = ["train-pose", "--data", str(tmp_path / "tr.npz"), "--val-data", str(tmp_path / "va.npz"),
              "--epochs", "1", "--threads", "1", "--quiet", "--set", "net.backbone=pointnet"]
    assert main([*common, "--out", str(tmp_path / "a"), "--set", "net.num_points=64"]) == 0
    init = str(tmp_path / "a" / "best.pt")
    assert main([*common, "--out", str(tmp_path / "b"), "--set", "net.num_points=64", "--init", init]) == 0
    assert main([*common, "--out", str(tmp_path / "c"), "--set", "net.num_points=128", "--init", init]) == 2
    assert main([*common, "--out", str(tmp_path / "d"), "--set", "net.num_points=64", "--init",
                 str(tmp_path / "no.pt")]) == 2


def test_cli_depth_smoothing_needs_a_detectors_scene_clouds(tmp_path, capsys) -> None:
    from perception.cli_pose import main

    base = ["train-pose", "--out", str(tmp_path / "x"), "--epochs", "1", "--quiet"]
    assert main([*base, "--set", "net.depth_smoothing_px=4"]) == 2  # rendered views: no depth image to smooth
    assert "net.depth_smoothing_px: needs --scenes" in capsys.readouterr().err
    assert main([*base, "--set", "net.depth_smoothing_px=4", "--scenes", str(tmp_path)]) == 2  # oracle masks
    assert "net.depth_smoothing_px: cuts a detector's clouds" in capsys.readouterr().err
    assert main([*base, "--set", "net.depth_smoothing_px=-2"]) == 2
    assert "--set: net.depth_smoothing_px: must be a number in [0, 20]" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_best_checkpoint_selected_by_axis_error(tmp_path, models) -> None:
    from perception.baselines.point_transformer.pose_net import read_checkpoint

    s = generate_samples(48, 5, models, FAST_VIEWS)
    net = PoseNetConfig(backbone="pointnet", num_points=64)
    ds = PointCloudPoseDataset(s[:32], 64)
    val = PointCloudPoseDataset(s[32:], 64)
    _, rows = train(net, TrainConfig(epochs=4, lr=3e-3, progress=False, select_by="axis"), ds, val, tmp_path)
    kept = read_checkpoint(tmp_path / "best.pt")
    best_row = min(rows, key=lambda r: r["val_mean_axis_deg"])
    assert kept["extra"]["epoch"] == best_row["epoch"]
    with pytest.raises(PerceptionConfigError, match="select_by"):
        TrainConfig(select_by="geodesic")


def test_ablation_writes_its_table_and_resumes(models, tmp_path, monkeypatch) -> None:
    from perception.baselines.point_transformer import ablation

    samples = generate_samples(24, seed=8, models=models, config=FAST_VIEWS)
    variants = [ablation.Variant("backbone", PoseNetConfig(backbone="pointnet", num_points=64)),
                ablation.Variant("head", PoseNetConfig(backbone="pointnet", head="6d_stem", num_points=64))]
    cfg = TrainConfig(epochs=1, batch_size=8, lr=1e-3, progress=False)
    rows = ablation.run_ablation(variants, samples[:16], samples[16:20], samples[20:], cfg, tmp_path)
    table = (tmp_path / "ablation.md").read_text()
    assert len(rows) == 2 and "6d_stem" in table and table.count("\n") == 4
    assert (tmp_path / "error_vs_angles.png").stat().st_size > 0 and (tmp_path / "error_vs_size.png").exists()
    # A rerun trains nothing and returns the stored rows; other settings are refused.
    monkeypatch.setattr(ablation, "train", lambda *a, **k: pytest.fail("resumed variant was trained again"))
    assert ablation.run_ablation(variants, samples[:16], samples[16:20], samples[20:], cfg, tmp_path) == rows
    with pytest.raises(ValueError, match="other settings"):
        ablation.run_ablation(variants, samples[:12], samples[16:20], samples[20:], cfg, tmp_path)


def _depth_by_ray(points: np.ndarray, focal_px: float) -> dict[tuple[int, int], float]:
    """Depth per pixel, keyed by the pixel's ray (x/z, y/z in pixels): the same key in a clean
    and a noisy view of the same pose whatever the noise did to the depth."""
    rays = np.rint(points[:, :2] / points[:, 2:3] * focal_px).astype(int)
    return {(int(u), int(v)): float(z) for (u, v), z in zip(rays, points[:, 2], strict=True)}


def test_camera_model_views_carry_the_stereo_noise_of_the_formula(models) -> None:
    """Same seed, same pose: the camera-model view's depth departs from the clean view's by the
    stereo RMS error σz = z²·s/(f·B) (D405, s = 0.08 px), correlated between neighbours, and the
    rim has flying pixels towards the soil."""
    upright = dict(tilt_std_deg=0.0, xy_range=0.0)
    residuals, sigmas, neighbour_pairs = [], [], []
    for seed in range(6):
        clean = render_view(models[0], np.random.default_rng(seed), ViewConfig(depth_noise_std=0.0, **upright))
        noisy = render_view(models[0], np.random.default_rng(seed), ViewConfig(camera_model=True, **upright))
        np.testing.assert_array_equal(clean.rotation, noisy.rotation)
        clean_z, noisy_z = _depth_by_ray(clean.points, 382.0), _depth_by_ray(noisy.points, 382.0)
        diff = {k: noisy_z[k] - clean_z[k] for k in clean_z.keys() & noisy_z.keys()}
        residuals += list(diff.values())
        sigmas += [clean_z[k] ** 2 * 0.08 / (382.0 * 0.018) for k in diff]
        neighbour_pairs += [(diff[k], diff[(k[0] + 1, k[1])]) for k in diff if (k[0] + 1, k[1]) in diff]
    r = np.array(residuals)
    robust_std = 1.4826 * np.median(np.abs(r - np.median(r)))
    assert robust_std == pytest.approx(np.mean(sigmas), rel=0.35)
    assert np.corrcoef(np.array(neighbour_pairs).T)[0, 1] > 0.5  # white noise would give ≈ 0
    # Flying pixels: rim pixels mixed towards the soil, far beyond the noise (5 sigma ≈ 8 mm).
    assert (r > 5 * np.array(sigmas)).sum() > 0


def test_gaps_in_the_splat_take_the_mushrooms_depth_not_the_soils() -> None:
    from perception.baselines.point_transformer.synthetic_views import _with_soil

    depth = np.full((9, 9), 0.35)
    valid = np.zeros((9, 9), bool)
    valid[2:7, 2:7] = True
    valid[4, 4] = False  # a pixel no surface sample hit, inside the mushroom
    depth[~valid] = np.inf  # as the splat leaves such pixels
    out = _with_soil(depth, valid, soil_depth=0.40)
    assert out[4, 4] == 0.35 and out[0, 0] == 0.40 and (out[valid] == 0.35).all()


def test_camera_model_views_are_deterministic(models) -> None:
    views = ViewConfig(camera_model=True, surface_samples=8000)
    a, b = generate_samples(2, 11, models, views), generate_samples(2, 11, models, views)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.points, y.points) and np.array_equal(x.colors, y.colors)


def test_cli_camera_model_views(tmp_path, capsys) -> None:
    from perception.cli_pose import main

    common = ["--epochs", "1", "--threads", "1", "--quiet", "--cache", str(tmp_path / "cache"), "--set",
              "net.backbone=pointnet", "net.num_points=64", "data.model_ids=[0]", "data.num_train=12", "data.num_val=4"]
    assert main(["train-pose", "--out", str(tmp_path / "a"), *common, "data.camera_model=true"]) == 0
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == [
        "train_n12_seed1_models0_camera.npz", "val_n4_seed2_models0_camera.npz"]
    assert main(["eval-pose", "--checkpoint", str(tmp_path / "a" / "best.pt"), "--num", "4", "--model-ids", "0",
                 "--threads", "1", "--camera-model"]) == 0
    capsys.readouterr()
    assert main(["train-pose", "--out", str(tmp_path / "b"), "--set", "data.camera_model=true", "--scenes",
                 str(tmp_path)]) == 2
    assert "data.camera_model: applies to rendered views: with --scenes set data.add_synthetic" in capsys.readouterr().err
    assert main(["eval-pose", "--camera-model", "--scenes", str(tmp_path)]) == 2
    assert "--camera-model applies to rendered views" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()
