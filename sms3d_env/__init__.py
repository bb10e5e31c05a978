"""Gymnasium environments for robotic mushroom picking (``SMS3DPick-v2``, ``SMS3DPickTrain-v2``:
the learnable training options; and the superseded ``-v1`` ids, whose picking model's rules rather
than the mushroom set the outcome). The ``-v0`` ids, with the Jaco whose links partly collide with
nothing, were removed: ``gym.make`` refuses them naming the latest version."""

# Importing generator first sets the headless rendering default (MUJOCO_GL=egl) before anything
# imports mujoco.
from gymnasium.envs.registration import register, registry

from generator.lazy import lazy_exports
from sms3d_env.physics_params import V1_PHYSICS

#: Public names and the submodules that define them; loaded on first access (PEP 562) so that
#: ``sms3d --help`` and the light submodules (the sweep's and training's parsers) do not pay for
#: MuJoCo and mink. The environment ids are registered here all the same: ``gym.make`` imports
#: ``sms3d_env.pick_env`` through the entry point.
_EXPORTS = {
    "ControllerConfig": "controller", "IKController": "controller",
    "SceneSourceConfig": "scene_source", "TargetRule": "targets", "RewardConfig": "rewards",
    "PregraspStart": "start_states", "ImageObservation": "cameras", "RenderCamera": "cameras",
    "PickPhysicsParams": "physics_params",
    "FAILURE_CAUSES": "picking_model", "SMS3DPickEnv": "pick_env",
    "EpisodeState": "episode_state", "PickingModel": "picking_model",
    "World": "world", "build_world": "world",
    "NoisyPose": "pose_sources", "OraclePose": "pose_sources", "PoseEstimate": "pose_sources",
    "PoseSource": "pose_sources", "UniformNoisyPose": "pose_sources", "make_pose_source": "pose_sources",
    "Tool": "tools", "TOOLS": "robot", "RobotConfig": "robot",
    "GantryConfig": "gantry", "ROBOTS": "robots", "make_robot": "robots", "register_robot": "robots",
    "registered_robots": "robots", "RobotSpec": "robots", "UR5eConfig": "ur5e",
    "HandPicker": "pickers.scripted", "ScriptedPicker": "pickers.scripted", "run_episode": "pickers.episode",
}  # fmt: skip

__all__ = sorted(_EXPORTS)

#: The training options of ``SMS3DPick-v2`` (see ``SMS3DPickEnv``): latched suction, the staged
#: reward, episodes that end at dead ends, and observations in the estimated target's frame.
TRAIN_OPTIONS = {"reward_type": "staged", "suction_mode": "latched", "end_on_dead_end": True,
                 "task_obs": True}

#: ``SMS3DPick-v1``'s options where they differ from v2's (the env's defaults; see
#: ``SMS3DPickEnv``'s version history): v1's picking model and the tallest reachable target.
V1_OPTIONS = {"robot": "gantry", "physics": V1_PHYSICS, "target": "tallest"}

#: The whole-bed harvest (:mod:`sms3d_env.harvest`): one bed per episode, picked mushroom after
#: mushroom in one world; the env ends its own episodes (stop, or ``HarvestConfig.max_actions``).
if "SMS3DHarvest-v0" not in registry:
    register(id="SMS3DHarvest-v0", entry_point="sms3d_env.harvest.env:SMS3DHarvestEnv")

for _id, _kw in (("SMS3DPick-v1", {"reward_type": "dense", **V1_OPTIONS}),
                 ("SMS3DPickTrain-v1", {**TRAIN_OPTIONS, **V1_OPTIONS}),
                 ("SMS3DPick-v2", {}),
                 ("SMS3DPickTrain-v2", TRAIN_OPTIONS)):
    if _id not in registry:
        register(id=_id, entry_point="sms3d_env.pick_env:SMS3DPickEnv", max_episode_steps=250, kwargs=_kw)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
