"""Training the axis CNN: crops labelled with the truth, the crop cache, a resumed run that
draws what an uninterrupted one does, the run folder's rule (resume, refuse, overwrite), and
the command's refusals."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import hashlib
import json
import shutil

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from generator.dataset.readers import read_scene_files, scene_indices
from generator.dataset.writer import scene_dirname
from generator.run_folder import SETTINGS_FILE, RunFolderError
from perception.baselines.point_transformer.estimator import default_weights_path
from perception.detection.detector import detections_from_labels
from perception.errors import PerceptionConfigError
from perception.pose.axis_cnn import SHIPPED_AXIS_CNN, AxisCNNConfig, load_axis_cnn
from perception.pose.train_axis_cnn import (
    AxisTrainConfig,
    CropSet,
    axis_loss,
    cached_crops,
    crops_from_detections,
    train_axis_cnn,
)


class _LabelDetector:
    """Detections from each scene's own instance labels, looked up by its RGB image."""

    def __init__(self, root):
        self.labels, self.calls = {}, 0
        for index in scene_indices(root, None):
            s = read_scene_files(root / scene_dirname(index))
            self.labels[hashlib.sha1(s.rgb.tobytes()).hexdigest()] = s.labels_mushroom

    def detect(self, rgb, depth):
        self.calls += 1
        return detections_from_labels(self.labels[hashlib.sha1(rgb.tobytes()).hexdigest()])


@pytest.fixture(scope="module")
def beds(small_dataset):
    root = small_dataset(4, 10, 31, (0.75, 0.25, 0.0))
    return root, _LabelDetector(root)


def test_crops_are_labelled_with_the_true_axis_in_their_ray_frame(beds) -> None:
    root, detector = beds
    crop_set = crops_from_detections(root, "train", detector)
    assert len(crop_set) >= 15 and crop_set.crops.dtype == np.float16
    from perception.pose.depth_crops import crop_around_mask

    for row, axis in zip(crop_set.meta[:5], crop_set.axes[:5]):
        s = read_scene_files(root / scene_dirname(int(row[0])))
        inst = next(i for i in s.record["instances"] if i["id"] == int(row[1]))
        mask = s.labels_mushroom == int(row[1]) + 1
        k = s.intrinsics
        crop = crop_around_mask(s.rgb, s.depth, mask, k.fx, k.fy, k.cx, k.cy)
        true_cam = np.asarray(s.world_from_camera)[:3, :3].T @ np.asarray(inst["rotation"])[:, 2]
        assert np.allclose(crop.ray_from_camera.T @ axis, true_cam, atol=1e-5)
        assert row[2] == pytest.approx(1.0)  # the labels' own masks match with IoU 1


def test_the_crop_cache_is_reused_for_the_same_detector_and_remade_otherwise(beds, tmp_path) -> None:
    root, detector = beds
    first = cached_crops(root, "val", detector, "a", tmp_path)
    calls = detector.calls
    again = cached_crops(root, "val", detector, "a", tmp_path)
    assert detector.calls == calls and np.array_equal(again.crops, first.crops)
    cached_crops(root, "val", detector, "b", tmp_path)
    assert detector.calls > calls
    (cache_file,) = tmp_path.glob("*.npz")
    cache_file.write_bytes(cache_file.read_bytes()[:100])  # cut short, as by a kill
    calls = detector.calls
    assert np.array_equal(cached_crops(root, "val", detector, "b", tmp_path).axes, first.axes)
    assert detector.calls > calls


def test_a_dataset_regenerated_at_the_same_path_gets_new_crops(tmp_path) -> None:
    # The cache was keyed on the folder's path: a dataset regenerated there got the old crops back.
    from generator import SceneConfig
    from generator.dataset import DatasetOptions, generate_dataset

    root = tmp_path / "beds"
    config = SceneConfig().replace(camera__width=256, camera__height=192, camera__height_above_soil=0.25,
                                   placement__num_mushrooms=6)
    crop_sets = []
    for seed in (1, 2):
        shutil.rmtree(root, ignore_errors=True)
        generate_dataset(root, config, 2, seed=seed, options=DatasetOptions(split_ratios=(1.0, 0.0, 0.0)), progress=False)
        detector = _LabelDetector(root)
        crop_sets.append(cached_crops(root, "train", detector, "a", tmp_path / "cache"))
        assert detector.calls == 2  # cut from this dataset's two scenes, not read from the cache
    assert len(crop_sets[1]) > 0 and not np.array_equal(crop_sets[0].crops, crop_sets[1].crops)


def test_a_rerun_resumes_a_finished_run_and_refuses_other_settings(beds, tmp_path, capsys) -> None:
    # A rerun trained anew and replaced best.pt with whatever it reached; another width was a
    # state-dict traceback and another learning rate, seed or loss went on unnoticed.
    root, detector = beds
    train, val = crops_from_detections(root, "train", detector), crops_from_detections(root, "val", detector)
    config = AxisTrainConfig(epochs=1, batch_size=8, warmup_iters=2)
    out = tmp_path / "run"
    torch.set_num_threads(1)
    first = train_axis_cnn(train, val, out, config, progress=False)
    written = {name: (out / name).read_bytes() for name in ("best.pt", "last.pt", "log.csv")}
    capsys.readouterr()
    assert train_axis_cnn(train, val, out, config, progress=False) == first
    assert f"{out} is complete (1 of 1 epochs)" in capsys.readouterr().err
    other = {"lr": {"config": AxisTrainConfig(epochs=1, batch_size=8, warmup_iters=2, lr=1e-2)},
             "seed": {"config": AxisTrainConfig(epochs=1, batch_size=8, warmup_iters=2, seed=1)},
             "loss": {"config": AxisTrainConfig(epochs=1, batch_size=8, warmup_iters=2, loss="cosine")},
             "width": {"config": config, "net": AxisCNNConfig(width=16)},
             "train_crops": {"config": config, "train": CropSet(train.crops[1:], train.axes[1:], train.meta[1:])}}
    for field, changed in other.items():
        with pytest.raises(RunFolderError, match=rf"other settings: {field} \(") as info:
            train_axis_cnn(**{"train": train, "val": val, "out": out, "progress": False, **changed})
        assert "--overwrite" in str(info.value)
    assert {name: (out / name).read_bytes() for name in written} == written
    train_axis_cnn(train, val, out, other["lr"]["config"], overwrite=True, progress=False)
    assert json.loads((out / SETTINGS_FILE).read_text())["lr"] == 1e-2


def test_a_resumed_run_ends_where_an_uninterrupted_one_does(beds, tmp_path, capsys) -> None:
    root, detector = beds
    train, val = crops_from_detections(root, "train", detector), crops_from_detections(root, "val", detector)
    config = AxisTrainConfig(epochs=3, batch_size=8, warmup_iters=2)
    torch.set_num_threads(1)
    straight = train_axis_cnn(train, val, tmp_path / "straight", config, progress=False)
    train_axis_cnn(train, val, tmp_path / "cut", AxisTrainConfig(epochs=3, batch_size=8, warmup_iters=2,
                                                                 time_limit_min=1e-6), progress=False)
    capsys.readouterr()
    resumed = train_axis_cnn(train, val, tmp_path / "cut", config, progress=False)  # the same settings: resumed
    assert f"resuming {tmp_path / 'cut'} from epoch 1 of 3" in capsys.readouterr().err
    assert resumed["val_mean_axis_deg"] == pytest.approx(straight["val_mean_axis_deg"], abs=1e-9)
    a = torch.load(tmp_path / "straight" / "last.pt", weights_only=True)["model"]
    b = torch.load(tmp_path / "cut" / "last.pt", weights_only=True)["model"]
    assert all(torch.equal(a[k], b[k]) for k in a)
    model, extra = load_axis_cnn(tmp_path / "straight" / "best.pt")
    assert extra["metrics"]["val_mean_axis_deg"] == straight["val_mean_axis_deg"]
    # A run started from a saved network begins from its weights, not the upright prior.
    warm = train_axis_cnn(train, val, tmp_path / "warm", AxisTrainConfig(epochs=1, batch_size=8, lr=1e-12),
                          progress=False, init=tmp_path / "straight" / "best.pt")
    assert warm["val_mean_axis_deg"] == pytest.approx(straight["val_mean_axis_deg"], abs=0.2)
    # A wider shape than the saved network's widens it, keeping what it had learnt.
    wide = train_axis_cnn(train, val, tmp_path / "wide", AxisTrainConfig(epochs=1, batch_size=8, lr=1e-12),
                          net=AxisCNNConfig(width=40, hidden=160), progress=False, init=tmp_path / "straight" / "best.pt")
    assert load_axis_cnn(tmp_path / "wide" / "best.pt")[0].config == AxisCNNConfig(width=40, hidden=160)
    assert wide["val_mean_axis_deg"] == pytest.approx(straight["val_mean_axis_deg"], abs=0.2)
    assert (tmp_path / "straight" / "log.csv").read_text().count("\n") == 4


def test_too_small_a_training_set_is_refused(beds, tmp_path) -> None:
    root, detector = beds
    val = crops_from_detections(root, "val", detector)
    with pytest.raises(PerceptionConfigError, match="batch_size"):
        train_axis_cnn(val, val, tmp_path, AxisTrainConfig(batch_size=10_000), progress=False)
    empty = CropSet(val.crops[:0], val.axes[:0], val.meta[:0])
    with pytest.raises(PerceptionConfigError, match="val"):
        train_axis_cnn(val, empty, tmp_path, AxisTrainConfig(batch_size=2), progress=False)


@given(st.floats(0.0, 3.14), st.floats(-3.14, 3.14))
def test_the_losses_are_the_angle_and_one_minus_its_cosine(angle: float, azimuth: float) -> None:
    target = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    axis = [np.sin(angle) * np.cos(azimuth), np.sin(angle) * np.sin(azimuth), np.cos(angle)]
    predicted = torch.tensor([axis], dtype=torch.float64, requires_grad=True)
    assert axis_loss(predicted, target, "angle").item() == pytest.approx(angle, abs=1e-5)
    assert axis_loss(predicted, target, "cosine").item() == pytest.approx(1.0 - np.cos(angle), abs=1e-9)
    axis_loss(predicted, target, "angle").backward()
    assert torch.isfinite(predicted.grad).all()  # finite where the axes agree too


def test_an_unknown_loss_is_refused() -> None:
    with pytest.raises(PerceptionConfigError, match="loss"):
        AxisTrainConfig(loss="l2")
    with pytest.raises(PerceptionConfigError, match="loss"):
        axis_loss(torch.zeros(1, 3), torch.zeros(1, 3), "l2")


@given(st.sampled_from(["epochs", "batch_size", "warmup_iters", "lr", "weight_decay", "time_limit_min"]),
       st.sampled_from([0, -1, float("nan"), float("inf"), True, 2.5]))
def test_bad_training_settings_name_their_field(name: str, value) -> None:
    ok = {"epochs": 0 < value if type(value) is int else False, "batch_size": type(value) is int and value > 0,
          "warmup_iters": type(value) is int and value >= 0,
          "lr": type(value) in (int, float) and np.isfinite(value) and value > 0,
          "weight_decay": type(value) in (int, float) and np.isfinite(value) and value >= 0,
          "time_limit_min": type(value) in (int, float) and np.isfinite(value) and value > 0}[name]
    if ok:
        AxisTrainConfig(**{name: value})
    else:
        with pytest.raises(PerceptionConfigError, match=name):
            AxisTrainConfig(**{name: value})


def test_the_command_refuses_oracle_masks_and_bad_settings(tmp_path, capsys) -> None:
    from sms3d_env.cli import main

    assert main(["train-axis-cnn", "--out", str(tmp_path), "--scenes", str(tmp_path), "--masks", "oracle"]) == 2
    assert "--masks" in capsys.readouterr().err
    assert main(["train-axis-cnn", "--out", str(tmp_path), "--scenes", str(tmp_path), "--epochs", "0"]) == 2
    assert "epochs" in capsys.readouterr().err
    # narrowing a saved network is refused before any crop is cut (the scenes folder is empty)
    assert main(["train-axis-cnn", "--out", str(tmp_path), "--scenes", str(tmp_path), "--init", str(SHIPPED_AXIS_CNN),
                 "--width", "16"]) == 2
    assert "width: can only grow" in capsys.readouterr().err
    assert main(["train-axis-cnn", "--out", str(tmp_path), "--scenes", str(tmp_path), "--init",
                 str(tmp_path / "missing.pt"), "--width", "48"]) == 2
    assert "missing.pt" in capsys.readouterr().err
    # an unset --hidden keeps the saved network's, so growing the width alone passes the check and
    # the command goes on to the scenes, where a folder without a dataset is named
    assert main(["train-axis-cnn", "--out", str(tmp_path / "out"), "--scenes", str(tmp_path), "--init",
                 str(SHIPPED_AXIS_CNN), "--width", str(load_axis_cnn(SHIPPED_AXIS_CNN)[0].config.width + 8)]) == 2
    err = capsys.readouterr().err
    assert "can only grow" not in err and "manifest.json" in err


def test_the_command_resumes_says_so_and_refuses_other_settings(beds, tmp_path, capsys) -> None:
    from sms3d_env.cli import main

    root, _ = beds
    out = tmp_path / "run"
    command = ["train-axis-cnn", "--out", str(out), "--scenes", str(root), "--cache", str(tmp_path / "cache"),
               "--batch-size", "4", "--threads", "1"]
    assert main([*command, "--epochs", "1"]) == 0
    capsys.readouterr()
    assert main([*command, "--epochs", "1"]) == 0  # used to train anew over the finished run
    assert f"{out} is complete" in capsys.readouterr().err
    assert main([*command, "--epochs", "2", "--resume"]) == 0
    assert f"resuming {out} from epoch 1 of 2" in capsys.readouterr().err
    best = (out / "best.pt").read_bytes()
    assert main([*command, "--epochs", "2", "--lr", "0.01", "--seed", "1", "--loss", "cosine", "--width", "16"]) == 2
    err = capsys.readouterr().err
    assert all(f"{field} (" in err for field in ("lr", "seed", "loss", "width")) and "--overwrite" in err
    assert (out / "best.pt").read_bytes() == best
    assert main([*command, "--epochs", "1", "--lr", "0.01", "--overwrite"]) == 0
    assert json.loads((out / SETTINGS_FILE).read_text())["lr"] == 0.01
    assert main([*command[:2], str(tmp_path / "new"), *command[3:], "--resume"]) == 2
    assert "holds no run to resume" in capsys.readouterr().err and not (tmp_path / "new").exists()


def test_the_command_checks_every_file_before_cutting_crops(beds, tmp_path, capsys) -> None:
    # --init of another network and --masks garbage were tracebacks, the first after every crop
    # was cut; a missing or repeated --scenes folder was found after the others were cropped.
    from sms3d_env.cli import main

    root, _ = beds
    (tmp_path / "garbage.pt").write_bytes(b"not a checkpoint")
    cache, out = tmp_path / "cache", tmp_path / "out"
    command = ["train-axis-cnn", "--out", str(out), "--cache", str(cache), "--scenes", str(root)]
    for flags, named in (
        (["--init", str(default_weights_path())], ("--init", default_weights_path().name, "not an axis-CNN checkpoint")),
        (["--masks", str(tmp_path / "garbage.pt")], ("--masks", "garbage.pt")),
        ([str(tmp_path / "missing")], ("--scenes", "missing", "manifest.json")),
        ([f"{root}/"], ("--scenes", "given twice")),
    ):
        assert main([*command, *flags]) == 2
        err = capsys.readouterr().err
        assert all(n in err for n in named), err
    assert not cache.exists() and not out.exists()
    assert main(["train-axis-cnn", "--out", "", "--scenes", str(tmp_path / "missing")]) == 2
    assert "--out must name a folder" in capsys.readouterr().err


def test_the_command_defaults_are_the_training_config_defaults() -> None:
    from perception.cli_pose import axis_train_config
    from sms3d_env.cli import build_parser

    parser = build_parser("train-axis-cnn")
    assert axis_train_config(parser.parse_args(["train-axis-cnn", "--out", "x", "--scenes", "y"])) == AxisTrainConfig()
    given = parser.parse_args(["train-axis-cnn", "--out", "x", "--scenes", "y", "--epochs", "3", "--loss", "cosine"])
    assert axis_train_config(given) == AxisTrainConfig(epochs=3, loss="cosine")
