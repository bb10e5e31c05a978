"""Pick policies trained with stable-baselines3 (PPO or SAC) on ``SMS3DPick-v0`` or on the
learnable options of ``SMS3DPickTrain-v0``.

``train_policy(TrainConfig(...))`` trains with vectorised envs (``SubprocVecEnv`` for
``n_envs > 1``, or all in this process with ``vec_env="dummy"``), evaluates periodically (``eval/success_rate`` from the env's ``is_success``),
writes CSV (and TensorBoard, if installed) logs, checkpoints and ``model.zip`` plus
``config.json`` and ``summary.json`` into ``out``; ``flat_observation`` trains an ``MlpPolicy`` on
the flattened observation; ``normalize=True`` standardises observations
(SB3's ``VecNormalize``, saved as ``vecnormalize.pkl`` beside the model). The demonstration-started
recipe lives in :mod:`sms3d_env.training.imitation`.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import Any

from sms3d_env.training.actor import VECNORM_FILE, observation_stats_path, saved_config_path
from sms3d_env.training.config import TrainConfig, env_options
from sms3d_env.training.curriculum import pregrasp_annealing
from sms3d_env.training.envs import normalized, vec_env
from sms3d_env.training.schedules import WallAwareLinearSchedule, trigger_noise_schedule
from sms3d_env.training.warmup import critic_warmup


def _tensorboard_available() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


def _build_model(cfg: TrainConfig, env: Any) -> Any:
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.utils import LinearSchedule

    rate: Any = cfg.learning_rate
    if cfg.learning_rate_by_wall:
        rate = WallAwareLinearSchedule(cfg.learning_rate, cfg.learning_rate_final, cfg.max_wall_s)
    elif cfg.learning_rate_final is not None:
        rate = LinearSchedule(cfg.learning_rate, cfg.learning_rate_final, end_fraction=1.0)
    policy_kwargs = {"net_arch": list(cfg.net_arch), "log_std_init": float(cfg.log_std_init)}
    policy = "MlpPolicy" if cfg.flat_observation else "MultiInputPolicy"
    if cfg.algo == "ppo":
        n_steps = cfg.n_steps
        batch = min(cfg.batch_size, n_steps * cfg.n_envs)
        return PPO(policy, env, learning_rate=rate, n_steps=n_steps,
                   batch_size=batch, gamma=cfg.gamma, target_kl=cfg.target_kl, policy_kwargs=policy_kwargs,
                   use_sde=cfg.use_sde, sde_sample_freq=cfg.sde_sample_freq,
                   seed=cfg.seed, device=cfg.device, verbose=cfg.verbose)
    return SAC(policy, env, learning_rate=rate, buffer_size=cfg.buffer_size,
               learning_starts=cfg.learning_starts, batch_size=cfg.batch_size, gamma=cfg.gamma,
               policy_kwargs=policy_kwargs, seed=cfg.seed, device=cfg.device, verbose=cfg.verbose)


class InitModelError(ValueError):
    """``TrainConfig.init_model`` is missing, lacks its observation statistics or does not fit."""


def _check_init_model(cfg: TrainConfig) -> None:
    """Before anything is written: ``cfg.init_model`` exists, is no file of ``cfg.out`` itself
    (that run's files would be overwritten), and brings what the run needs
    (``InitModelError`` naming the file)."""
    path = Path(cfg.init_model)
    if not path.is_file():
        raise InitModelError(f"TrainConfig.init_model: no saved model at {path}")
    out = Path(cfg.out).resolve()
    if out in (path.resolve().parent, path.resolve().parent.parent):
        raise InitModelError(f"TrainConfig.init_model: {path} belongs to the output folder {cfg.out}; "
                             "a continued run needs an out of its own")
    saved = saved_config_path(path)
    saved_cfg = {} if saved is None else json.loads(saved.read_text())
    trigger = bool(saved_cfg.get("residual_descend_trigger", False))
    if trigger != cfg.residual_descend_trigger:
        raise InitModelError(f"TrainConfig.init_model: {path} was trained {'with' if trigger else 'without'} the "
                             f"residual's descend trigger ({8 if trigger else 7} actions); set "
                             f"residual_descend_trigger={trigger} to start from it")
    trigger_only = bool(saved_cfg.get("residual_trigger_only", False))
    if trigger_only != cfg.residual_trigger_only:
        raise InitModelError(f"TrainConfig.init_model: {path} was trained {'with' if trigger_only else 'without'} "
                             f"residual_trigger_only ({1 if trigger_only else 8} actions); set "
                             f"residual_trigger_only={trigger_only} to start from it")
    flat = bool(saved_cfg.get("flat_observation", False))
    if flat != cfg.flat_observation:
        raise InitModelError(f"TrainConfig.init_model: {path} was trained on "
                             f"{'flattened' if flat else 'dict'} observations; set flat_observation={flat} "
                             f"({'with' if flat else 'without'} --flat-observation) to start from it")
    stats = observation_stats_path(path)
    if cfg.normalize and stats is None:
        raise InitModelError(f"TrainConfig.init_model: no observation statistics saved with {path} "
                             f"(normalize=True needs {VECNORM_FILE} or the checkpoint's own)")
    if not cfg.normalize and stats is not None:
        raise InitModelError(f"TrainConfig.init_model: {path} was trained on normalised observations "
                             f"({stats.name}); set normalize=True (--normalize) to start from it")


def _set_trigger_exploration(model: Any, cfg: TrainConfig) -> None:
    """The descend trigger's log standard deviation (the action's last entry): ``cfg.trigger_log_std``, or
    for a fresh policy ``DESCEND_TRIGGER_LOG_STD_INIT`` (an ``init_model`` keeps its own)."""
    if not cfg.residual_descend_trigger or (cfg.trigger_log_std is None and cfg.init_model is not None):
        return
    from sms3d_env.training.residual import DESCEND_TRIGGER_LOG_STD_INIT, set_trigger_log_std

    set_trigger_log_std(model.policy, DESCEND_TRIGGER_LOG_STD_INIT if cfg.trigger_log_std is None
                        else cfg.trigger_log_std)


def _start_from(model: Any, env: Any, cfg: TrainConfig) -> None:
    """``cfg.init_model``: its weights into ``model`` and, with ``normalize``, its observation
    statistics into ``env`` (``InitModelError`` naming the file)."""
    import pickle

    _check_init_model(cfg)
    path = Path(cfg.init_model)
    try:
        if cfg.use_sde:
            _start_sde_from(model, path, cfg.device)
        else:
            model.set_parameters(str(path), exact_match=True, device=cfg.device)
    except (ValueError, RuntimeError, KeyError) as exc:
        raise InitModelError(f"TrainConfig.init_model: {path} does not fit a {cfg.algo} policy with "
                             f"net_arch {list(cfg.net_arch)} on {cfg.env_id} ({exc})") from None
    if cfg.normalize:
        with open(observation_stats_path(path), "rb") as f:
            env.obs_rms = pickle.load(f).obs_rms


def _start_sde_from(model: Any, path: Path, device: str) -> None:
    """A gSDE run from a saved policy: its networks and, from a gSDE policy, its noise; from a
    Gaussian policy (whose log standard deviation has another shape and meaning) this run's
    noise and a fresh optimiser."""
    from stable_baselines3.common.save_util import load_from_zip_file

    _, params, _ = load_from_zip_file(str(path), device=device)
    if params["policy"]["log_std"].shape == model.policy.log_std.shape:
        model.set_parameters(params, exact_match=True, device=device)
        return
    weights = {k: v for k, v in params["policy"].items() if k != "log_std"}
    missing, unexpected = model.policy.load_state_dict(weights, strict=False)
    if unexpected or set(missing) != {"log_std"}:
        raise ValueError(f"missing {sorted(set(missing) - {'log_std'})}, unexpected {sorted(unexpected)}")


def _save_beside_best(env: Any, out: Path, normalize: bool) -> Any:
    """A callback for ``EvalCallback``'s new best: the run's ``config.json`` and, with
    ``normalize``, the observation statistics of that moment beside ``best/best_model.zip``, so
    that ``eval-policy`` and the sweep load the best model as they load the final one (the
    statistics keep changing after it)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _SaveBesideBest(BaseCallback):
        def _on_step(self) -> bool:
            best = out / "best"
            best.mkdir(parents=True, exist_ok=True)
            if normalize:
                env.save(str(best / VECNORM_FILE))
            (best / "config.json").write_text((out / "config.json").read_text())
            return True

    return _SaveBesideBest()


def _wall_clock_callback(max_wall_s: float) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class _StopAfter(BaseCallback):
        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter()

        def _on_step(self) -> bool:
            return time.perf_counter() - self.t0 < max_wall_s

    return _StopAfter()


def _observation_keys(cfg: TrainConfig) -> list[str]:
    """The observation's keys in the order ``FlattenObservation`` concatenates them (saved so that
    ``PolicyActor`` flattens a dict observation the same way)."""
    from sms3d_env.training.envs import make_env

    env = make_env(**{**cfg.env_kwargs(), "flat_observation": False})
    try:
        return list(env.observation_space.spaces)
    finally:
        env.close()


def train_policy(cfg: TrainConfig) -> dict[str, Any]:
    """Train, log and save a policy; returns a summary (also written to ``out/summary.json``).

    Files in ``cfg.out``: ``model.zip`` (final), ``config.json``, ``summary.json``,
    ``progress.csv`` (SB3 logger; ``eval/success_rate`` rows after each evaluation),
    TensorBoard events if ``tensorboard`` is installed, ``checkpoints/``, ``best/best_model.zip``,
    ``eval/evaluations.npz`` and ``monitor/`` (per-episode return, length, is_success).
    """
    from sms3d_env.training.threads import torch_threads

    # A SubprocVecEnv for training and a DummyVecEnv for evaluation is intended here.
    warnings.filterwarnings("ignore", message="Training and eval env are not of the same type")

    with torch_threads(cfg.torch_threads):
        return _train(cfg)


def _train(cfg: TrainConfig) -> dict[str, Any]:
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback, EvalCallback
    from stable_baselines3.common.logger import configure

    if cfg.init_model is not None:
        _check_init_model(cfg)
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    saved = {**asdict(cfg), "env_options": env_options(cfg.posture_target)}
    if cfg.flat_observation:
        saved["observation_keys"] = _observation_keys(cfg)
    (out / "config.json").write_text(json.dumps(saved, indent=2))
    env = vec_env(cfg.env_kwargs(), cfg.n_envs, cfg.seed, str(out / "monitor"), cfg.vec_env)
    if cfg.normalize:
        env = normalized(env, training=True, reward_gamma=cfg.gamma if cfg.normalize_reward else None)
    eval_env = None
    try:
        model = _build_model(cfg, env)
        if cfg.init_model is not None:
            _start_from(model, env, cfg)
        _set_trigger_exploration(model, cfg)
        formats = ["stdout", "csv"] + (["tensorboard"] if _tensorboard_available() else [])
        if not cfg.verbose:
            formats.remove("stdout")
        model.set_logger(configure(str(out), formats))
        callbacks: list[Any] = []
        if cfg.eval_freq > 0:
            # Periodic evaluation under the training pose condition (fixed seeds): fresh beds, not
            # the training pool's, and every episode from home.
            eval_kw = {k: v for k, v in cfg.env_kwargs().items() if k not in ("scene_pool", "pregrasp_start")}
            eval_env = vec_env(eval_kw, 1, cfg.seed + 10_000, None)
            if cfg.normalize:
                # EvalCallback copies the training statistics into it before each evaluation.
                eval_env = normalized(eval_env, training=False)
            callbacks.append(EvalCallback(
                eval_env, n_eval_episodes=cfg.eval_episodes, eval_freq=max(cfg.eval_freq // cfg.n_envs, 1),
                log_path=str(out / "eval"), best_model_save_path=str(out / "best"),
                callback_on_new_best=_save_beside_best(env, out, cfg.normalize),
                deterministic=True, verbose=cfg.verbose, warn=False))
        if cfg.checkpoint_freq > 0:
            callbacks.append(CheckpointCallback(max(cfg.checkpoint_freq // cfg.n_envs, 1),
                                                str(out / "checkpoints"), name_prefix=cfg.algo,
                                                save_vecnormalize=cfg.normalize))
        if cfg.pregrasp_anneal:
            callbacks.append(pregrasp_annealing(cfg.pregrasp_start))
        if cfg.critic_warmup_steps:
            callbacks.append(critic_warmup(cfg.critic_warmup_steps))
        if cfg.trigger_log_std_final is not None:
            callbacks.append(trigger_noise_schedule(cfg.trigger_log_std, cfg.trigger_log_std_final, cfg.max_wall_s))
        if cfg.max_wall_s is not None:
            callbacks.append(_wall_clock_callback(cfg.max_wall_s))
        t0 = time.perf_counter()
        model.learn(total_timesteps=cfg.total_steps, callback=CallbackList(callbacks),
                    progress_bar=False)
        wall = time.perf_counter() - t0
        model.save(str(out / "model.zip"))
        if cfg.normalize:
            env.save(str(out / VECNORM_FILE))
        summary = {
            "algo": cfg.algo, "steps": int(model.num_timesteps), "wall_s": round(wall, 1),
            "steps_per_s": round(model.num_timesteps / wall, 1) if wall > 0 else math.nan,
            "n_envs": cfg.n_envs, "pose_source": cfg.pose_source, "pose_error_deg": cfg.pose_error_deg,
            "model": str(out / "model.zip"), "tensorboard": "tensorboard" in formats,
        }
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        return summary
    finally:
        env.close()
        if eval_env is not None:
            eval_env.close()
