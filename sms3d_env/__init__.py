"""Gymnasium environments for robotic mushroom picking (``SMS3DPick-v0``, ``SMS3DPickSparse-v0``)."""

import os

# Headless rendering by default; set before anything imports mujoco (and picks a GL backend).
os.environ.setdefault("MUJOCO_GL", "egl")

from gymnasium.envs.registration import register, registry  # noqa: E402

from sms3d_env.controller import ControllerConfig, IKController
from sms3d_env.physics import PickPhysicsParams
from sms3d_env.pick_env import FAILURE_CAUSES, SMS3DPickEnv
from sms3d_env.pose_source import NoisyPose, OraclePose, PoseEstimate, PoseSource, make_pose_source
from sms3d_env.robot import TOOLS, RobotConfig
from sms3d_env.scripted_picker import HandPicker, ScriptedPicker, run_episode

for _id, _kw in (("SMS3DPick-v0", {"reward_type": "dense"}),
                 ("SMS3DPickSparse-v0", {"reward_type": "sparse"})):
    if _id not in registry:
        register(id=_id, entry_point="sms3d_env.pick_env:SMS3DPickEnv", max_episode_steps=250,
                 kwargs=_kw)

__all__ = [
    "FAILURE_CAUSES", "ControllerConfig", "HandPicker", "IKController", "NoisyPose", "OraclePose",
    "PickPhysicsParams", "PoseEstimate", "PoseSource", "RobotConfig", "SMS3DPickEnv",
    "ScriptedPicker", "TOOLS", "make_pose_source", "run_episode",
]
