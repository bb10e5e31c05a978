"""``samples_from_detections``: training clouds cut out by a stage-1 detector's masks, matched to
the truth, optionally trimmed as the pipeline will trim them."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from generator.dataset.readers import read_scene_files
from generator.dataset.writer import scene_dirname
from perception.baselines.point_transformer.data import samples_from_detections
from perception.detection.detector import detections_from_labels
from perception.pipeline import within_depth_of_core


class _SpillingDetector:
    """The renderer's masks grown by two pixels onto whatever lies around them, as a learned
    mask spills over a cap's rim."""

    def detect(self, rgb, depth):
        labels = self.labels
        out = []
        for det in detections_from_labels(labels):
            grown = cv2.dilate(det.mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
            out.append(dataclasses.replace(det, mask=grown))
        return out


@pytest.fixture(scope="module")
def spilling_bed(small_dataset):
    """A one-scene dataset, its scene, and a detector whose masks spill over its mushrooms."""
    root = small_dataset(1, 6, 21, (1.0, 0.0, 0.0))
    scene = read_scene_files(root / scene_dirname(0))
    detector = _SpillingDetector()
    detector.labels = scene.labels_mushroom
    return root, scene, detector


def test_trimmed_training_clouds_lose_the_soil_their_masks_spilled_onto(spilling_bed):
    root, scene, detector = spilling_bed
    whole = samples_from_detections(root, "train", detector, num_points=256)
    trimmed = samples_from_detections(root, "train", detector, num_points=256,
                                      cloud_pixels=lambda m, d: (within_depth_of_core(m, d, 0.008), d))
    assert len(whole) == len(trimmed) >= 3
    spilled = kept = 0
    for w, t in zip(whole, trimmed, strict=True):
        assert w.meta["instance_id"] == t.meta["instance_id"]
        assert np.array_equal(w.rotation, t.rotation)  # the same truth
        truth = np.count_nonzero((scene.labels_mushroom == w.meta["instance_id"] + 1) & (scene.depth > 0))
        assert truth <= t.meta["num_valid"] <= w.meta["num_valid"]  # never into the mushroom itself
        spilled, kept = spilled + w.meta["num_valid"] - truth, kept + t.meta["num_valid"] - truth
    # What stays lies on neighbours or beside the stem's foot, at the mushroom's own depth.
    assert kept < 0.4 * spilled


def test_training_clouds_carry_the_colours_of_their_pixels(spilling_bed):
    root, scene, detector = spilling_bed
    samples = samples_from_detections(root, "train", detector, num_points=256)
    rgb = scene.rgb.astype(np.float32) / 255.0
    for s in samples:
        assert s.colors.shape == s.points.shape and s.colors.dtype == np.float32
        # Each point's colour is the RGB of the pixel its depth came from.
        u = np.rint(s.points[:, 0] / s.points[:, 2] * scene.intrinsics.fx + scene.intrinsics.cx).astype(int)
        v = np.rint(s.points[:, 1] / s.points[:, 2] * scene.intrinsics.fy + scene.intrinsics.cy).astype(int)
        assert np.allclose(s.colors, rgb[v, u], atol=1e-6)
