"""The shipped stage-1 model: it loads from the package without a download, finds the mushrooms
of a freshly rendered bed, and is what the pipeline, the perception pose source and the commands
use unless told otherwise."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest
import torch

from perception.baselines.point_transformer.estimator import PoseEstimator
from perception.detection.detector import detections_from_labels, mask_iou
from perception.detection.load import SHIPPED_SEGMENTER, describe_detector, load_detector
from perception.detection.rgbd_segmenter import RGBDSegmenter
from perception.pipeline import PosePipeline
from perception.pose.axis_cnn import SHIPPED_AXIS_CNN
from sms3d_env.pose_sources import PerceptionPose


@pytest.fixture(scope="module")
def bed_frame(render_bed):
    """A 640 x 480 bed of 15 mushrooms (a seed no training set used), rendered cleanly."""
    return render_bed(15, 424242)[1]


def test_the_shipped_segmenter_is_small_and_loads_without_a_download(monkeypatch):
    assert SHIPPED_SEGMENTER.is_file() and SHIPPED_SEGMENTER.stat().st_size < 20e6
    monkeypatch.setattr(torch.hub, "load_state_dict_from_url", lambda *a, **k: pytest.fail("download attempted"))
    detector = load_detector("shipped")
    assert isinstance(detector, RGBDSegmenter)
    assert load_detector("oracle") is None
    assert "shipped" in describe_detector("shipped") and "oracle" in describe_detector("oracle")


def test_the_shipped_segmenter_finds_the_mushrooms_of_a_rendered_bed(bed_frame):
    truth = [d for d in detections_from_labels(bed_frame.labels_mushroom) if d.area >= 200]
    found = load_detector("shipped").detect(bed_frame.rgb, bed_frame.depth)
    assert len(truth) >= 10
    matched = sum(max((mask_iou(g.mask, d.mask) for d in found), default=0.0) >= 0.5 for g in truth)
    assert matched >= 0.9 * len(truth), f"{matched}/{len(truth)} mushrooms found"
    assert len(found) <= len(truth) + 3  # few false detections


def test_the_pipeline_and_the_perception_source_default_to_the_shipped_segmenter():
    pipeline = PosePipeline(PoseEstimator.from_pretrained())
    assert isinstance(pipeline.detector, RGBDSegmenter)
    assert PosePipeline(pipeline.estimator, "oracle").detector is None
    source = PerceptionPose()
    assert isinstance(source._pipeline().detector, RGBDSegmenter)
    assert source._pipeline().axis_model.path == SHIPPED_AXIS_CNN  # stage 2: the shipped axis CNN
    assert PerceptionPose(detector="oracle")._pipeline().detector is None


def test_a_missing_detector_file_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.pt"):
        load_detector(str(tmp_path / "nothing.pt"))
