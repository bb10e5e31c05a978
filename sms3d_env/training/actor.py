"""A saved pick policy as a picker: ``load_model`` and ``PolicyActor`` (observation statistics and
the env it was trained on from the files beside it); ``SHIPPED_POLICY`` is the shipped one."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sms3d_env.training.config import ALGOS

#: The shipped pick policy (``model.zip`` with its ``config.json``, ``README.md``, metrics).
SHIPPED_POLICY = Path(__file__).parents[1] / "weights" / "pick_policy" / "model.zip"
VECNORM_FILE = "vecnormalize.pkl"


def load_model(model_path: str | Path, algo: str | None = None) -> Any:
    """Load a saved PPO/SAC model; the algorithm comes from ``config.json`` beside it if not given."""
    from stable_baselines3 import PPO, SAC

    path = Path(model_path)
    if algo is None:
        cfg_file = path.parent / "config.json"
        if cfg_file.exists():
            algo = json.loads(cfg_file.read_text()).get("algo")
    if algo is not None:
        if algo not in ALGOS:
            raise ValueError(f"algo must be one of {ALGOS}, got {algo!r}")
        return (PPO if algo == "ppo" else SAC).load(str(path), device="cpu")
    try:
        return PPO.load(str(path), device="cpu")
    except Exception:  # not a PPO archive
        return SAC.load(str(path), device="cpu")


class PolicyActor:
    """A saved SB3 model as ``actor(obs) -> action``, its observation statistics applied when a
    ``vecnormalize.pkl`` lies beside it. ``env_id``/``env_options``: what it was trained on
    (``config.json`` beside the model; ``SMS3DPick-v0`` with no options if there is none)."""

    def __init__(self, model_path: str | Path, algo: str | None = None, deterministic: bool = True) -> None:
        path = Path(model_path)
        if not path.is_file():
            raise FileNotFoundError(f"model not found: {path}")
        self.path, self.deterministic = path, deterministic
        self.saved: dict[str, Any] = {}
        if (path.parent / "config.json").is_file():
            self.saved = json.loads((path.parent / "config.json").read_text())
        self.env_id = self.saved.get("env_id", "SMS3DPick-v0")
        self.env_options = dict(self.saved.get("env_options", {}))
        self.residual_scale = float(self.saved.get("residual_scale", 0.0))
        self.model = load_model(path, algo)
        self.obs_stats = None
        if (path.parent / VECNORM_FILE).is_file():
            import pickle

            with open(path.parent / VECNORM_FILE, "rb") as f:
                self.obs_stats = pickle.load(f)  # SB3 VecNormalize, saved by train_policy

    def __call__(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        if self.obs_stats is not None:
            obs = self.obs_stats.normalize_obs(obs)
        action, _ = self.model.predict(obs, deterministic=self.deterministic)
        return action
