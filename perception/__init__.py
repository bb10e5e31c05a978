"""Mushroom perception from one RGB-D image, in two stages.

Stage 1 finds each mushroom's mask (the shipped RGB-D segmenter,
:mod:`perception.detection.rgbd_segmenter`); stage 2 maps an RGB-D crop around each mask to the
stem axis (the shipped :class:`~perception.pose.axis_cnn.AxisCNNEstimator`).
:class:`~perception.pipeline.PosePipeline` puts them together and adds the cap top. The SMS3D
paper's Mask R-CNN and Point Transformer are kept as baselines in :mod:`perception.baselines`.
"""

import generator  # noqa: F401  (sets the headless rendering default, MUJOCO_GL=egl, before mujoco is imported)
from perception.errors import CheckpointMismatchError, NoEstimate, PerceptionConfigError

__all__ = ["CheckpointMismatchError", "NoEstimate", "PerceptionConfigError"]
