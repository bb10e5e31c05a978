"""Pose sources: where the target mushroom's *estimated* pose in the observation comes from.

| source | module |
| --- | --- |
| ``PoseEstimate``, the ``PoseSource`` protocol | :mod:`~sms3d_env.pose_sources.base` |
| ``"oracle"`` (``OraclePose``), ``"noisy"`` (``NoisyPose``, ``UniformNoisyPose``) | :mod:`~sms3d_env.pose_sources.noisy` |
| ``"perception"`` (``PerceptionPose``: the two-stage pipeline on the overhead RGB-D) | :mod:`~sms3d_env.pose_sources.perception` |

Every module here imports only numpy at load time (the perception pipeline, torch and the
renderer load when ``PerceptionPose`` is first called); ``base`` imports no other pose source.
"""

from __future__ import annotations

from sms3d_env.pose_sources.base import PoseEstimate, PoseSource
from sms3d_env.pose_sources.noisy import NoisyPose, OraclePose, UniformNoisyPose
from sms3d_env.pose_sources.perception import PerceptionPose

__all__ = ["NoisyPose", "OraclePose", "PerceptionPose", "PoseEstimate", "PoseSource",
           "UniformNoisyPose", "make_pose_source"]


def make_pose_source(kind: str | PoseSource, pose_error_deg: float = 0.0,
                     position_std: float = 0.0,
                     pose_error_range_deg: tuple[float, float] | None = None) -> PoseSource:
    """``"oracle"``, ``"noisy"`` (with ``pose_error_range_deg``: :class:`UniformNoisyPose`, the
    error drawn per episode), ``"perception"`` (the two-stage pipeline with the shipped pose
    network, :class:`PerceptionPose`) or any callable pose source."""
    if callable(kind):
        return kind
    if kind == "noisy" and pose_error_range_deg is not None:
        return UniformNoisyPose(*pose_error_range_deg)
    if kind == "oracle":
        return OraclePose()
    if kind == "noisy":
        return NoisyPose(pose_error_deg, position_std)
    if kind == "perception":
        return PerceptionPose()
    raise ValueError(f"pose_source must be 'oracle', 'noisy', 'perception' or a callable, got {kind!r}")
