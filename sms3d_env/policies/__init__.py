"""Saved pick policies: their files, and loading one without running code from it.

| concept | module |
| --- | --- |
| loading a saved model (``load_sb3``, ``load_model``), its run's files (``saved_config_path``, ``observation_stats_path``), the shipped policy (``SHIPPED_POLICY``) | :mod:`~sms3d_env.policies.loader` |
| a model's files: atomic saves with the policy's description, observation statistics without pickles (``save_model``, ``ObservationStats``, ``PolicyFileError``) | :mod:`~sms3d_env.policies.files` |
| what a model's policy is built from instead of SB3's pickled entries (``PolicySpec``) | :mod:`~sms3d_env.policies.spec` |
| the env a saved policy runs in (``make_env``, ``match_env``) | :mod:`~sms3d_env.policies.envs` |
| runs that RL Baselines3 Zoo saved (``zoo_run_of``, ``read_vecnormalize``) | :mod:`~sms3d_env.policies.zoo_runs` |
| the shipped policy's features extractor (``NormalizedFlatten``) | :mod:`~sms3d_env.policies.features` |

The policy picker that acts with a saved policy is :class:`sms3d_env.pickers.policy.PolicyActor`;
training writes these files (:mod:`sms3d_env.training`). The names load their module on first
access.
"""

from generator.lazy import lazy_exports

_EXPORTS = {
    "SHIPPED_POLICY": "loader", "load_model": "loader", "load_sb3": "loader",
    "OBS_STATS_FILE": "files", "ObservationStats": "files", "PolicyFileError": "files", "save_model": "files",
    "PolicySpec": "spec", "make_env": "envs", "zoo_run_of": "zoo_runs", "NormalizedFlatten": "features",
}  # fmt: skip

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
