"""The "perception" pose source: oracle masks or a learned detector's masks feed the pose network."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
import dataclasses

import numpy as np
import pytest

from perception.baselines.point_transformer.estimator import PoseEstimator
from perception.detection.detector import detections_from_labels
from perception.pipeline import PosePipeline
from sms3d_env.pose_sources.perception import PerceptionPose


class LabelDetector:
    """Masks of a fixed label image without instance ids: what a learned detector returns."""

    def __init__(self, labels, keep=True):
        self.detections = [dataclasses.replace(d, instance_id=None) for d in detections_from_labels(labels)] if keep else []

    def detect(self, rgb, depth=None):
        return self.detections


@pytest.fixture(scope="module")
def scene_and_labels(render_bed):
    scene, frame = render_bed(8, 3, 320, 240)
    labels = frame.labels_mushroom
    target = max(range(len(scene.instances)), key=lambda i: (labels == i + 1).sum())  # the most visible
    return scene, labels, target


def test_a_learned_detectors_mask_gives_the_oracle_estimate(scene_and_labels):
    scene, labels, target = scene_and_labels
    estimator = PoseEstimator.from_pretrained()
    oracle = PerceptionPose(PosePipeline(estimator, None))
    learned = PerceptionPose(PosePipeline(estimator, LabelDetector(labels)))
    a = oracle(scene, target, np.random.default_rng(0))
    b = learned(scene, target, np.random.default_rng(0))
    # Same mask, same network; only the network's random point subsampling differs between a
    # one-mushroom call and a whole-scene batch.
    assert np.degrees(np.arccos(np.clip(a.stem_axis @ b.stem_axis, -1, 1))) < 5.0
    assert np.linalg.norm(a.cap_top - b.cap_top) < 0.003
    assert oracle.fallbacks == learned.fallbacks == 0
    assert learned.last_axis_error_deg < 45.0
    oracle.close()
    learned.close()


def test_a_missed_target_falls_back_upright_and_is_counted(scene_and_labels):
    scene, labels, target = scene_and_labels
    source = PerceptionPose(PosePipeline(PoseEstimator.from_pretrained(), LabelDetector(labels, keep=False)))
    estimate = source(scene, target, np.random.default_rng(0))
    assert source.fallbacks == 1 and np.allclose(estimate.rotation, np.eye(3))
    assert np.allclose(estimate.cap_top, scene.instances[target].cap_top)
    source.close()


def test_realism_frames_are_drawn_from_the_episode_rng(scene_and_labels):
    """With ``realism=True`` the camera's noise, shadows and jitter come from the episode's
    generator: the same seed gives the same estimate, another seed another one. (A fresh
    estimator per call: its own point sampling is seeded once, at construction.)"""
    scene, _, target = scene_and_labels

    def estimate(seed, realism=True):
        source = PerceptionPose(PosePipeline(PoseEstimator.from_pretrained(views=1), None), realism=realism)
        return source(scene, target, np.random.default_rng(seed))

    a, b, c, clean = estimate(5), estimate(5), estimate(6), estimate(5, realism=False)
    assert np.array_equal(a.cap_top, b.cap_top) and np.array_equal(a.rotation, b.rotation)
    assert not np.array_equal(a.cap_top, c.cap_top) and not np.array_equal(a.cap_top, clean.cap_top)
    assert np.linalg.norm(a.cap_top - clean.cap_top) < 0.02  # noise, not another mushroom
