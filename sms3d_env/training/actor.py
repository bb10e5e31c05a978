"""A saved pick policy as a picker: ``load_model`` and ``PolicyActor`` (observation statistics and
the env it was trained on from the files beside it); ``SHIPPED_POLICY`` is the shipped one, and
``SHIPPED_TRIGGER`` the shipped descend trigger (a residual picker)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sms3d_env.training.config import ALGOS

#: The shipped pick policy (``model.zip`` with its ``config.json``, ``README.md``, metrics).
SHIPPED_POLICY = Path(__file__).parents[1] / "weights" / "pick_policy" / "model.zip"
#: The shipped descend trigger: a trigger-only residual learned from counterfactual rollouts
#: (:mod:`sms3d_env.training.trigger_rollouts`), with its ``config.json``, ``README.md``, metrics.
SHIPPED_TRIGGER = Path(__file__).parents[1] / "weights" / "descend_trigger" / "model.zip"
VECNORM_FILE = "vecnormalize.pkl"


def _checkpoint_parts(path: Path) -> tuple[str, str] | None:
    """``("ppo", "1400000_steps")`` for SB3 ``CheckpointCallback``'s ``ppo_1400000_steps.zip``."""
    algo, _, rest = path.stem.partition("_")
    return (algo, rest) if rest.endswith("_steps") and rest[: -len("_steps")].isdigit() else None


def checkpoint_steps(path: str | Path) -> int | None:
    """The env steps in a ``CheckpointCallback`` file name (``ppo_1400000_steps.zip`` -> 1400000)."""
    parts = _checkpoint_parts(Path(path))
    return None if parts is None else int(parts[1][: -len("_steps")])


def saved_config_path(model_path: str | Path) -> Path | None:
    """The ``config.json`` of a model's run: beside it, or for a checkpoint in the run's
    ``checkpoints/`` folder the run folder's; ``None`` when there is none."""
    path = Path(model_path)
    for folder in (path.parent, path.parent.parent if _checkpoint_parts(path) else None):
        if folder is not None and (folder / "config.json").is_file():
            return folder / "config.json"
    return None


def observation_stats_path(model_path: str | Path) -> Path | None:
    """The ``VecNormalize`` statistics saved with a model: ``vecnormalize.pkl`` beside it, or for
    a checkpoint ``<algo>_<N>_steps.zip`` its ``<algo>_vecnormalize_<N>_steps.pkl`` (SB3's
    ``CheckpointCallback`` naming); ``None`` when there are none."""
    path = Path(model_path)
    beside = path.parent / VECNORM_FILE
    if beside.is_file():
        return beside
    parts = _checkpoint_parts(path)
    checkpoint = None if parts is None else path.parent / f"{parts[0]}_vecnormalize_{parts[1]}.pkl"
    return checkpoint if checkpoint is not None and checkpoint.is_file() else None


def _no_rate(_progress_remaining: float) -> float:
    return 0.0


def load_model(model_path: str | Path, algo: str | None = None) -> Any:
    """Load a saved PPO/SAC model for acting; the algorithm comes from ``config.json`` beside it if
    not given. Its learning-rate schedule is not unpickled (acting needs none, and a schedule class
    a run was saved with, e.g. :class:`~sms3d_env.training.schedules.WallAwareLinearSchedule`,
    need not be importable where the model is used)."""
    from stable_baselines3 import PPO, SAC

    path = Path(model_path)
    no_schedule = {"learning_rate": 0.0, "lr_schedule": _no_rate}
    if algo is None:
        cfg_file = saved_config_path(path)
        if cfg_file is not None:
            algo = json.loads(cfg_file.read_text()).get("algo")
    if algo is not None:
        if algo not in ALGOS:
            raise ValueError(f"algo must be one of {ALGOS}, got {algo!r}")
        return (PPO if algo == "ppo" else SAC).load(str(path), device="cpu", custom_objects=no_schedule)
    try:
        return PPO.load(str(path), device="cpu", custom_objects=no_schedule)
    except Exception:  # not a PPO archive
        return SAC.load(str(path), device="cpu", custom_objects=no_schedule)


class PolicyActor:
    """A saved SB3 model as ``actor(obs) -> action``, its observation statistics applied when they
    were saved with it (:func:`observation_stats_path`). ``env_id``/``env_options``: what it was trained on
    (:func:`saved_config_path`; ``SMS3DPick-v0`` with no options if there is none)."""

    def __init__(self, model_path: str | Path, algo: str | None = None, deterministic: bool = True) -> None:
        path = Path(model_path)
        if not path.is_file():
            raise FileNotFoundError(f"model not found: {path}")
        self.path, self.deterministic = path, deterministic
        cfg_file = saved_config_path(path)
        self.saved: dict[str, Any] = {} if cfg_file is None else json.loads(cfg_file.read_text())
        self.env_id = self.saved.get("env_id", "SMS3DPick-v0")
        self.env_options = dict(self.saved.get("env_options", {}))
        self.residual_scale = float(self.saved.get("residual_scale", 0.0))
        self.residual_until_held = bool(self.saved.get("residual_until_held", False))
        self.residual_approach_only = bool(self.saved.get("residual_approach_only", False))
        self.residual_descend_trigger = bool(self.saved.get("residual_descend_trigger", False))
        self.residual_trigger_only = bool(self.saved.get("residual_trigger_only", False))
        # A policy trained on the flattened observation: the keys in their concatenation order.
        self.observation_keys: list[str] | None = self.saved.get("observation_keys")
        if self.saved.get("flat_observation") and self.observation_keys is None:
            raise ValueError(f"{cfg_file}: flat_observation is set but observation_keys (the flattening "
                             "order) is missing; retrain, or add the keys of the env's observation space")
        self.model = load_model(path, algo)
        self.obs_stats = None
        stats = observation_stats_path(path)
        if stats is not None:
            import pickle

            with open(stats, "rb") as f:
                self.obs_stats = pickle.load(f)  # SB3 VecNormalize, saved by train_policy

    def make_env(self, **kwargs: Any) -> Any:
        """The env this policy runs in: its env id and options, inside the residual wrapper it
        was trained in (if any), with ``kwargs`` (bed size, pose source, ...) for the rest. Its
        observation is the dict one even for a policy trained on the flattened observation
        (``__call__`` flattens it)."""
        from sms3d_env.training.envs import make_env

        return make_env(self.env_id, self.residual_scale, self.residual_until_held, self.residual_approach_only,
                        self.residual_descend_trigger, residual_trigger_only=self.residual_trigger_only,
                        **{**kwargs, **self.env_options})

    def __call__(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        if self.observation_keys is not None:  # as gymnasium's FlattenObservation did in training
            obs = np.concatenate([np.ravel(obs[k]) for k in self.observation_keys])
        if self.obs_stats is not None:
            obs = self.obs_stats.normalize_obs(obs)
        action, _ = self.model.predict(obs, deterministic=self.deterministic)
        return action
