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


def make_pose_source(kind: str | PoseSource, error_deg: float | tuple[float, float] = 0.0) -> PoseSource:
    """``"oracle"``, ``"noisy"`` (rotated by exactly ``error_deg``, :class:`NoisyPose`; a ``(low,
    high)`` pair: the error drawn per episode, :class:`UniformNoisyPose`), ``"perception"`` (the
    two-stage pipeline with the shipped pose network, :class:`PerceptionPose`) or any callable pose
    source (a ``NoisyPose`` with position noise, a ``PerceptionPose`` with another detector)."""
    if callable(kind):
        return kind
    if kind == "oracle":
        return OraclePose()
    if kind == "noisy":
        return UniformNoisyPose(*error_deg) if isinstance(error_deg, tuple) else NoisyPose(error_deg)
    if kind == "perception":
        return PerceptionPose()
    raise ValueError(f"pose_source must be 'oracle', 'noisy', 'perception' or a callable, got {kind!r}")
