"""The training envs: pick envs (:func:`~sms3d_env.policies.envs.make_env`) vectorised
(``vec_env``) and with standardised observations (``normalized``)."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

from sms3d_env.policies.envs import make_env


def vec_env(kwargs: dict[str, Any], n_envs: int, seed: int, monitor_dir: str | None,
            kind: str = "subproc", continue_monitor: bool = False) -> Any:
    """``n_envs`` monitored envs seeded ``seed + i``: in worker processes (``kind="subproc"``,
    when ``n_envs`` > 1) or in this process (``"dummy"``). ``continue_monitor`` (a resumed run):
    append to the monitor files in ``monitor_dir`` where all of them exist (SB3's ``Monitor``
    truncates them otherwise, and appends no header to a new one)."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    append = continue_monitor and monitor_dir is not None and all(
        (Path(monitor_dir) / f"{i}.monitor.csv").is_file() for i in range(n_envs))  # make_vec_env's names
    return make_vec_env(functools.partial(make_env, **kwargs), n_envs=n_envs, seed=seed,
                        monitor_dir=monitor_dir,
                        vec_env_cls=SubprocVecEnv if n_envs > 1 and kind == "subproc" else DummyVecEnv,
                        monitor_kwargs={"info_keywords": ("is_success", "failure_cause", "start"),
                                        "override_existing": not append})


def normalized(env: Any, training: bool, reward_gamma: float | None = None) -> Any:
    """Observations standardised by running statistics. Rewards as they are unless
    ``reward_gamma`` is given: then scaled by the running standard deviation of the return
    discounted with it (SB3's ``norm_reward``; for training only: evaluation reports true
    returns)."""
    from stable_baselines3.common.vec_env import VecNormalize

    return VecNormalize(env, norm_obs=True, norm_reward=reward_gamma is not None,
                        gamma=0.99 if reward_gamma is None else reward_gamma, training=training)
