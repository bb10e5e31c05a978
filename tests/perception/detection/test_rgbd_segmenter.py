"""The RGB-D segmenter: targets that decode to the ground truth, training that learns and
resumes, checkpoints, and errors that name what is wrong."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dataclasses import replace

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from generator.dataset.readers import read_scene_files
from generator.dataset.writer import scene_dirname
from generator.run_folder import RunFolderError
from perception.detection.detector import detections_from_labels, mask_iou
from perception.detection.rgbd_segmenter import (
    OFFSET_SCALE,
    RGBDSegmenter,
    build_segmenter,
    instances_from_heads,
    load_segmenter,
    save_segmenter,
)
from perception.detection.segmenter_config import SegmenterConfig, SegmenterTrainConfig
from perception.detection.segmenter_data import SegmenterDataset, segmenter_targets
from perception.detection.train_segmenter import train_segmenter
from perception.errors import CheckpointFormatError, PerceptionConfigError, PipelineInputError


@pytest.fixture(scope="module")
def beds(small_dataset):
    """Four 256 x 192 beds of 8 mushrooms seen from 25 cm, in the train and val splits."""
    return small_dataset(4, 8, 11, (0.5, 0.5, 0.0))


def _logit(p: np.ndarray) -> np.ndarray:
    p = np.clip(p, 1e-4, 1 - 1e-4)
    return np.log(p / (1 - p))


def test_perfect_heads_decode_to_the_ground_truth_instances(beds):
    """The targets and the decoding agree: heads equal to the targets give back every instance
    (at half resolution the masks lose only their border pixels)."""
    config = SegmenterConfig()
    for i in range(4):
        s = read_scene_files(beds / scene_dirname(i))
        t = segmenter_targets(s.rgb, s.depth, s.labels_mushroom, config.centre_sigma_px)
        heads = torch.from_numpy(np.stack([_logit(t.mushroom), _logit(t.centre), *t.offset]).astype(np.float32))
        found = instances_from_heads(heads, s.rgb.shape[:2], config)
        truth = [d for d in detections_from_labels(s.labels_mushroom) if d.area >= config.min_area]
        assert len(found) == len(truth) >= 5
        ious = [max(mask_iou(g.mask, d.mask) for d in found) for g in truth]
        assert min(ious) > 0.6 and np.mean(ious) > 0.85


def test_augmented_offsets_still_point_at_their_instance_centre(beds):
    """Flips and transposes move offsets with the pixels: every labelled pixel of a crop plus its
    offset lands on the centroid of its instance's pixels (as the crop was cut)."""
    torch.manual_seed(0)
    data = SegmenterDataset([beds / scene_dirname(0)], crop=64)
    for _ in range(8):
        inputs, mushroom, _, _, offset, weight = data[0]
        assert inputs.shape == (5, 64, 64) and offset.shape == (2, 64, 64)
        vs, us = torch.nonzero(weight > 0, as_tuple=True)
        pointed_u = us + offset[0, vs, us] * OFFSET_SCALE
        pointed_v = vs + offset[1, vs, us] * OFFSET_SCALE
        # pixels of one instance point at one place
        keys = torch.round(torch.stack([pointed_u, pointed_v], 1) * 100)
        assert len(torch.unique(keys, dim=0)) <= 12
        assert torch.all(mushroom[vs, us] == 1)


def test_training_resumes_from_its_last_epoch_and_refuses_other_settings(beds, small_dataset, tmp_path, capsys):
    train = SegmenterTrainConfig(epochs=2, batch_size=2, crop=64, lr=3e-3, warmup_iters=1, val_every=1, max_val_images=1)
    small, run = SegmenterConfig(widths=(8, 8, 16, 16, 16)), tmp_path / "run"
    log = train_segmenter([beds], run, small, train, progress=False)
    assert [r["epoch"] for r in log] == [1, 2] and "val_mask_f1" in log[-1]
    assert (run / "best.pt").is_file() and (run / "log.csv").is_file()
    longer = replace(train, epochs=3)
    capsys.readouterr()
    log = train_segmenter([beds], run, small, longer, progress=False)
    assert [r["epoch"] for r in log] == [1, 2, 3]  # resumed: epochs 1-2 come from last.pt
    assert f"resuming {run} from epoch 2 of 3" in capsys.readouterr().err
    # Another network was refused; other data, rate, crop or seed went on from the checkpoint.
    for field, changed in {"widths": {"config": SegmenterConfig()}, "lr": {"train": replace(longer, lr=1e-3)},
                           "crop": {"train": replace(longer, crop=48)}, "seed": {"train": replace(longer, seed=1)},
                           "data": {"roots": [small_dataset(2, 6, 5, (1.0, 0.0, 0.0))]}}.items():
        with pytest.raises(RunFolderError, match=rf"{field} \("):
            train_segmenter(**{"roots": [beds], "out": run, "config": small, "train": longer, "progress": False,
                               **changed})
    assert [r["epoch"] for r in train_segmenter([beds], run, small, longer, overwrite=True, progress=False)] == [1, 2, 3]


def test_the_command_refuses_a_batch_larger_than_the_training_images(beds, tmp_path, capsys):
    # It trained on no batch at all and saved the untrained network, exit 0.
    from sms3d_env.cli import main

    out = tmp_path / "run"
    assert main(["train-segmenter", "--data", str(beds), "--out", str(out), "--batch-size", "4", "--crop", "64",
                 "--epochs", "1"]) == 2
    err = capsys.readouterr().err
    assert "--batch-size" in err and "the 3 training images" in err and not out.exists()


def test_a_saved_segmenter_detects_the_same_after_loading(beds, tmp_path):
    torch.manual_seed(0)
    config = SegmenterConfig(widths=(8, 8, 16, 16, 16), centre_threshold=0.01)
    model = build_segmenter(config)
    with torch.no_grad():
        model.centre_head.bias.fill_(0.0)  # some peaks even untrained
        model.mask_head.bias.fill_(5.0)
    save_segmenter(tmp_path / "seg.pt", model, config)
    s = read_scene_files(beds / scene_dirname(0))
    before = RGBDSegmenter(model, config).detect(s.rgb, s.depth)
    after = load_segmenter(tmp_path / "seg.pt").detect(s.rgb, s.depth)
    assert len(before) == len(after) > 0
    for a, b in zip(before, after):
        assert a.box == b.box and np.array_equal(a.mask, b.mask) and a.score == pytest.approx(b.score)
        assert a.mask.shape == s.rgb.shape[:2] and a.area >= config.min_area


def test_errors_name_what_is_wrong(beds, tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointFormatError, match="bad.pt"):
        load_segmenter(bad)
    with pytest.raises(FileNotFoundError, match="missing.pt"):
        load_segmenter(tmp_path / "missing.pt")
    small = SegmenterConfig(widths=(8, 8, 16, 16, 16))
    save_segmenter(tmp_path / "other.pt", build_segmenter(small), SegmenterConfig())  # weights of another network
    with pytest.raises(CheckpointFormatError, match="other.pt: weights do not fit"):
        load_segmenter(tmp_path / "other.pt")
    segmenter = RGBDSegmenter(build_segmenter(), SegmenterConfig())
    s = read_scene_files(beds / scene_dirname(0))
    with pytest.raises(PipelineInputError, match="depth"):
        segmenter.detect(s.rgb)
    with pytest.raises(PipelineInputError, match="rgb"):
        segmenter.detect(s.rgb.astype(np.float32), s.depth)
    with pytest.raises(PerceptionConfigError, match="crop"):
        SegmenterDataset([beds / scene_dirname(0)], crop=200)


@given(st.sampled_from(["mask_threshold", "centre_threshold", "score_threshold"]),
       st.one_of(st.floats(max_value=0.0), st.floats(min_value=1.0), st.just(float("nan"))))
def test_thresholds_outside_zero_one_are_refused_by_name(name, value):
    with pytest.raises(PerceptionConfigError, match=name):
        SegmenterConfig(**{name: value})


@given(st.sampled_from(["epochs", "batch_size", "crop", "val_every", "max_val_images"]), st.integers(max_value=0))
def test_training_counts_below_one_are_refused_by_name(name, value):
    with pytest.raises(PerceptionConfigError, match=name):
        SegmenterTrainConfig(**{name: value})
