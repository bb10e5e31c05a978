"""Mushroom pose perception: point clouds, rotation representations, pose networks.

Stage 2 of the SMS3D pipeline, two ways: an RGB-D crop around each mushroom's mask is mapped by
the :class:`~perception.pose.axis_cnn.AxisCNN` to its stem axis (the shipped pipeline's default,
:class:`~perception.pose.axis_cnn.AxisCNNEstimator`), or its point cloud (camera frame, OpenCV
convention) by a :class:`~perception.pose.pose_net.PoseNet` to a rotation whose third column is
the stem axis (:class:`~perception.pose.estimator.PoseEstimator`, the paper's Point Transformer).
:class:`~perception.pipeline.PosePipeline` puts stage 1 and stage 2 together.
"""

from perception.errors import CheckpointMismatchError, NoEstimate, PerceptionConfigError

__all__ = ["CheckpointMismatchError", "NoEstimate", "PerceptionConfigError"]
