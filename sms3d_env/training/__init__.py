"""Training pick policies: RL recipes run by RL Baselines3 Zoo's trainer, behaviour cloning +
DAgger on Minari datasets by the package's own.

| concept | module |
| --- | --- |
| ``sms3d train-policy`` on an RL recipe: RL Zoo's command line and trainer (``zoo_argv``, ``train_zoo``) | :mod:`~sms3d_env.training.zoo` |
| the package's callbacks that RL recipes name: the falling rate and the wall-clock limit (``falling_learning_rate``, ``wall_clock_limit``, ``WallAwareLinearSchedule``) | :mod:`~sms3d_env.training.schedules` |
| the start-state curriculum that follows home-start success (``pregrasp_annealing``) | :mod:`~sms3d_env.training.curriculum` |
| the env arguments every recipe and command builds its envs from (``env_kwargs``) | :mod:`~sms3d_env.training.envs` |
| behaviour cloning + DAgger of the scripted picker (``BCConfig``, ``train_bc``) | :mod:`~sms3d_env.training.imitation` |
| demonstrations as Minari datasets (``record_datasets``, ``labelled_steps``, ``ExpertLabels``) | :mod:`~sms3d_env.training.demonstrations` |
| ``sms3d record-demos`` | :mod:`~sms3d_env.training.cli_demos` |
| recipes as data: a shipped recipe or a recipe file (``read_recipe``, ``Recipe``) | :mod:`~sms3d_env.training.recipes` |
| success of a saved policy (``evaluate_policy_success``) | :mod:`~sms3d_env.training.evaluation` |
| learning curves of runs (``read_curve``, ``sms3d learning-curve``) | :mod:`~sms3d_env.training.learning_curve` |
| ``sms3d train-policy`` / ``eval-policy`` (``register``, ``main``; ``python -m sms3d_env.training``) | :mod:`~sms3d_env.training.cli` |

A saved policy's files and their loading live in :mod:`sms3d_env.policies`, the policy picker in
:mod:`sms3d_env.pickers.policy`. The names load their module on first access (``sms3d --help``
pays for none of SB3 or torch).
"""

from generator.lazy import lazy_exports

_EXPORTS = {
    "zoo_argv": "zoo", "train_zoo": "zoo", "WallAwareLinearSchedule": "schedules", "env_kwargs": "envs",
    "BCConfig": "imitation", "train_bc": "imitation",
    "record_datasets": "demonstrations", "labelled_steps": "demonstrations", "Recipe": "recipes", "read_recipe": "recipes",
    "evaluate_policy_success": "evaluation", "success_line": "evaluation",
    "read_curve": "learning_curve", "register": "cli", "main": "cli",
}  # fmt: skip

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
