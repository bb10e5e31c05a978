"""Loading a checkpoint never runs code from it: every loader in perception reads tensors and
plain values only (``torch.load(weights_only=True)``), and a file that pickles anything else is
refused with ``CheckpointFormatError`` naming it. The shipped weights are such files."""

from pathlib import Path

import numpy as np
import pytest
import torch

from perception.baselines.maskrcnn.model import MaskRCNNDetector
from perception.baselines.point_transformer.config import PoseNetConfig, TrainConfig
from perception.baselines.point_transformer.data import PointCloudPoseDataset, PointCloudSample
from perception.baselines.point_transformer.estimator import default_weights_path
from perception.baselines.point_transformer.pose_net import load_checkpoint
from perception.baselines.point_transformer.train import train
from perception.detection.load import SHIPPED_SEGMENTER, load_detector
from perception.detection.rgbd_segmenter import load_segmenter
from perception.errors import CheckpointFormatError
from perception.pose.axis_cnn import SHIPPED_AXIS_CNN, load_axis_cnn
from perception.pose.depth_crops import CROP_CHANNELS, CROP_SIZE
from perception.pose.train_axis_cnn import AxisTrainConfig, CropSet, train_axis_cnn


class _TouchOnLoad:
    """Unpickling this calls ``Path.touch(marker)``: a stand-in for whatever a crafted file could run."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def _craft(path: Path, marker: Path) -> None:
    torch.save({"format": "any", "payload": _TouchOnLoad(marker)}, path)


def test_the_crafted_file_would_run_its_code_if_unpickled(tmp_path):
    _craft(tmp_path / "crafted.pt", tmp_path / "marker")
    torch.load(tmp_path / "crafted.pt", weights_only=False)
    assert (tmp_path / "marker").exists()  # so the tests below test something


LOADERS = {
    "segmenter": load_segmenter,  # --detector, --masks, --checkpoint, --perception-detector
    "mask-rcnn": MaskRCNNDetector.from_checkpoint,
    "any-detector": lambda path: load_detector(str(path)),
    "axis-cnn": load_axis_cnn,  # --weights, --init
    "pose-net": load_checkpoint,  # --weights, --checkpoint, --init
}


@pytest.mark.parametrize("load", LOADERS.values(), ids=LOADERS)
def test_a_crafted_checkpoint_is_refused_and_runs_nothing(tmp_path, load):
    _craft(tmp_path / "crafted.pt", tmp_path / "marker")
    with pytest.raises(CheckpointFormatError, match="crafted.pt"):
        load(tmp_path / "crafted.pt")
    assert not (tmp_path / "marker").exists()


def test_a_crafted_training_state_is_refused_on_resume(tmp_path):
    rng = np.random.default_rng(0)
    samples = [PointCloudSample(rng.normal(size=(64, 3)).astype(np.float32), np.eye(3, dtype=np.float32))
               for _ in range(4)]
    data, net = PointCloudPoseDataset(samples, 32), PoseNetConfig(backbone="pointnet", num_points=32, hidden=8)
    train(net, TrainConfig(epochs=1, batch_size=2, progress=False), data, data, tmp_path / "pose")
    crops = CropSet(rng.normal(size=(4, CROP_CHANNELS, CROP_SIZE, CROP_SIZE)).astype(np.float16),
                    np.tile(np.float32([0, 0, -1]), (4, 1)), np.zeros((4, 6)))
    train_axis_cnn(crops, crops, tmp_path / "axis", AxisTrainConfig(epochs=1, batch_size=2), progress=False)
    for state in (tmp_path / "pose" / "train_state.pt", tmp_path / "axis" / "last.pt"):
        _craft(state, tmp_path / "marker")
    with pytest.raises(CheckpointFormatError, match="train_state.pt"):
        train(net, TrainConfig(epochs=2, batch_size=2, progress=False), data, data, tmp_path / "pose")
    with pytest.raises(CheckpointFormatError, match="last.pt"):
        train_axis_cnn(crops, crops, tmp_path / "axis", AxisTrainConfig(epochs=2, batch_size=2), progress=False)
    assert not (tmp_path / "marker").exists()


@pytest.mark.parametrize("path", [SHIPPED_SEGMENTER, SHIPPED_AXIS_CNN, default_weights_path()], ids=lambda p: p.name)
def test_the_shipped_weights_hold_only_tensors_and_plain_values(path):
    assert isinstance(torch.load(path, map_location="cpu", weights_only=True), dict)
