"""Learned pick policies with stable-baselines3.

| concept | module |
| --- | --- |
| ``TrainConfig`` (RL settings, saved as ``config.json``), ``env_kwargs`` | :mod:`~sms3d_env.training.config` |
| the training envs (``vec_env``, ``normalized``) | :mod:`~sms3d_env.training.envs` |
| PPO/SAC training (``train_policy``) | :mod:`~sms3d_env.training.rl` |
| a falling rate that ends by steps or by wall clock (``WallAwareLinearSchedule``) | :mod:`~sms3d_env.training.schedules` |
| the start-state curriculum that follows home-start success (``pregrasp_annealing``) | :mod:`~sms3d_env.training.curriculum` |
| behaviour cloning + DAgger of the scripted picker (``BCConfig``, ``train_bc``) | :mod:`~sms3d_env.training.imitation` |
| demonstrations as Minari datasets (``record_datasets``, ``labelled_steps``, ``ExpertLabels``) | :mod:`~sms3d_env.training.demonstrations` |
| ``sms3d record-demos`` | :mod:`~sms3d_env.training.cli_demos` |
| recipes as data: a shipped recipe or a recipe file as a config (``read_recipe``, ``Recipe``) | :mod:`~sms3d_env.training.recipes` |
| RL Baselines3 Zoo: the recipe files (``with_recipe``) | :mod:`~sms3d_env.training.zoo` |
| success of a saved policy (``evaluate_policy_success``) | :mod:`~sms3d_env.training.evaluation` |
| learning curves of runs (``read_curve``, ``sms3d learning-curve``) | :mod:`~sms3d_env.training.learning_curve` |
| ``sms3d train-policy`` / ``eval-policy`` (``register``, ``main``; ``python -m sms3d_env.training``) | :mod:`~sms3d_env.training.cli` |

The names load their module on first access (``sms3d --help`` pays for none of SB3 or torch).
"""

from generator.lazy import lazy_exports

_EXPORTS = {
    "ALGOS": "config", "ENV_IDS": "config", "POSE_SOURCES": "config",
    "REWARD_TYPES": "config", "TrainConfig": "config", "env_kwargs": "config",
    "train_policy": "rl", "WallAwareLinearSchedule": "schedules",
    "BCConfig": "imitation", "train_bc": "imitation",
    "record_datasets": "demonstrations", "labelled_steps": "demonstrations", "with_recipe": "zoo", "Recipe": "recipes", "read_recipe": "recipes",
    "evaluate_policy_success": "evaluation", "success_line": "evaluation",
    "read_curve": "learning_curve", "register": "cli", "main": "cli",
}  # fmt: skip

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
