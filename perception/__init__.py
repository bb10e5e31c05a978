"""Mushroom pose perception: point clouds, rotation representations, pose networks.

Stage 2 of the SMS3D pipeline: a per-mushroom point cloud (camera frame, OpenCV convention) is
mapped by a :class:`~perception.pose.pose_net.PoseNet` to a rotation whose third column is the stem
axis. :class:`~perception.pose.estimator.PoseEstimator` wraps a trained network for inference.
"""

from perception.errors import CheckpointMismatchError, NoEstimate, PerceptionConfigError

__all__ = ["CheckpointMismatchError", "NoEstimate", "PerceptionConfigError"]
