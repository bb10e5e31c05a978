"""Pick policies trained with stable-baselines3 (PPO or SAC) on ``SMS3DPick-v2`` or on the
learnable options of ``SMS3DPickTrain-v2`` (or their superseded v1 ids).

``train_policy(TrainConfig(...))`` trains with vectorised envs (``SubprocVecEnv`` for
``n_envs > 1``, or all in this process with ``vec_env="dummy"``), evaluates periodically (``eval/success_rate`` from the env's ``is_success``),
writes CSV (and TensorBoard, if installed) logs, checkpoints and ``model.zip`` plus
``config.json`` and ``summary.json`` into ``out``; ``flat_observation`` trains an ``MlpPolicy`` on
the flattened observation; ``normalize=True`` standardises observations
(SB3's ``VecNormalize``; its statistics saved as ``obs_rms.npz`` beside the model, no pickle).
``out`` is a run folder (:mod:`generator.run_folder`): a rerun with the same settings resumes
from the latest complete checkpoint, other settings are refused unless ``overwrite``. Every file
is written atomically (:mod:`sms3d_env.policies.files`). The demonstration-started recipe
lives in :mod:`sms3d_env.training.imitation`.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import time
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from generator.files import write_atomic
from generator.run_folder import open_run_folder
from sms3d_env.policies.files import (
    OBS_STATS_FILE,
    ObservationStats,
    PolicyFileError,
    finished_run,
    load_replay_buffer,
    run_settings,
    save_model,
    save_replay_buffer,
)
from sms3d_env.policies.loader import (
    checkpoint_path,
    checkpoint_steps,
    load_sb3,
    observation_stats_path,
    read_saved_config,
    saved_config_path,
)
from sms3d_env.policies.spec import PolicySpec, algorithm_class
from sms3d_env.training.config import TrainConfig, env_options, removed_experiment_of
from sms3d_env.training.curriculum import pregrasp_annealing
from sms3d_env.training.envs import normalized, vec_env
from sms3d_env.training.schedules import falling_rate


def _tensorboard_available() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


def _model_arguments(cfg: TrainConfig) -> tuple[str, dict[str, Any]]:
    """The SB3 policy name and keyword arguments of ``cfg``'s PPO/SAC model: what
    :func:`_build_model` builds it with and what a resumed run loads its checkpoint with
    (:func:`_resume_from`)."""
    rate: Any = cfg.learning_rate
    if cfg.learning_rate_final is not None:
        rate = falling_rate(cfg.learning_rate, cfg.learning_rate_final,
                            cfg.max_wall_s if cfg.learning_rate_by_wall else None)
    policy_kwargs = {"net_arch": list(cfg.net_arch), "log_std_init": float(cfg.log_std_init)}
    policy = "MlpPolicy" if cfg.flat_observation else "MultiInputPolicy"
    common = dict(learning_rate=rate, gamma=cfg.gamma, policy_kwargs=policy_kwargs, seed=cfg.seed, device=cfg.device,
                  verbose=cfg.verbose)
    if cfg.algo == "ppo":
        return policy, dict(common, n_steps=cfg.n_steps, batch_size=min(cfg.batch_size, cfg.n_steps * cfg.n_envs),
                            target_kl=cfg.target_kl)
    return policy, dict(common, buffer_size=cfg.buffer_size, learning_starts=cfg.learning_starts,
                        batch_size=cfg.batch_size)


def _build_model(cfg: TrainConfig, env: Any) -> Any:
    policy, kwargs = _model_arguments(cfg)
    return algorithm_class(cfg.algo)(policy, env, **kwargs)


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
    saved_cfg = {} if saved is None else read_saved_config(saved)
    removed = removed_experiment_of(saved_cfg)
    if removed:
        raise InitModelError(f"TrainConfig.init_model: {path} is a residual policy: {removed}")
    flat = bool(saved_cfg.get("flat_observation", False))
    if flat != cfg.flat_observation:
        raise InitModelError(f"TrainConfig.init_model: {path} was trained on "
                             f"{'flattened' if flat else 'dict'} observations; set flat_observation={flat} "
                             f"({'with' if flat else 'without'} --flat-observation) to start from it")
    stats = observation_stats_path(path)
    if cfg.normalize and stats is None:
        raise InitModelError(f"TrainConfig.init_model: no observation statistics saved with {path} "
                             f"(normalize=True needs {OBS_STATS_FILE} or the checkpoint's own)")
    if not cfg.normalize and stats is not None:
        raise InitModelError(f"TrainConfig.init_model: {path} was trained on normalised observations "
                             f"({stats.name}); set normalize=True (--normalize) to start from it")


def _start_from(model: Any, env: Any, cfg: TrainConfig) -> None:
    """``cfg.init_model``: its weights into ``model`` and, with ``normalize``, its observation
    statistics into ``env`` (``InitModelError`` naming the file)."""
    _check_init_model(cfg)
    path = Path(cfg.init_model)
    try:
        model.set_parameters(str(path), exact_match=True, device=cfg.device)
    except (ValueError, RuntimeError, KeyError) as exc:
        raise InitModelError(f"TrainConfig.init_model: {path} does not fit a {cfg.algo} policy with "
                             f"net_arch {list(cfg.net_arch)} on {cfg.env_id} ({exc})") from None
    if cfg.normalize:
        try:
            ObservationStats.load(observation_stats_path(path)).apply_to(env)
        except ValueError as exc:
            raise InitModelError(f"TrainConfig.init_model: {path}: {exc}") from None


def _check_init_model_fits(cfg: TrainConfig) -> None:
    """``cfg.init_model`` loaded into a throwaway model on one env in this process, before the
    run folder is opened: weights that do not fit are found only by building the network, and a
    refusal must leave ``cfg.out`` as it was (``InitModelError`` naming the file)."""
    env = vec_env(cfg.env_kwargs(), 1, cfg.seed, None, "dummy")
    if cfg.normalize:
        env = normalized(env, training=True)
    try:
        _start_from(_build_model(cfg, env), env, cfg)
    finally:
        env.close()


def _save_model_and_stats(model: Any, env: Any, normalize: bool, model_path: Path, stats_path: Path) -> None:
    """``model`` and, with ``normalize``, ``env``'s observation statistics of this moment, each
    atomically; the model last, so that a model on disk always has its statistics beside it."""
    model_path.parent.mkdir(parents=True, exist_ok=True)
    if normalize:
        ObservationStats.of(env).save(stats_path)
    save_model(model, model_path)


def _save_best(env: Any, out: Path, normalize: bool) -> Any:
    """A callback for ``EvalCallback``'s new best: ``best/best_model.zip`` with the run's
    ``config.json`` and, with ``normalize``, the observation statistics of that moment beside it,
    so that ``eval-policy`` and the sweep load the best model as they load the final one (the
    statistics keep changing after it)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _SaveBest(BaseCallback):
        def _on_step(self) -> bool:
            best = out / "best"
            best.mkdir(parents=True, exist_ok=True)
            write_atomic(best / "config.json", (out / "config.json").read_text())
            _save_model_and_stats(self.model, env, normalize, best / "best_model.zip", best / OBS_STATS_FILE)
            return True

    return _SaveBest()


def _checkpoints(env: Any, folder: Path, cfg: TrainConfig) -> Any:
    """An SB3 callback: a checkpoint in ``folder`` each time the run passes a multiple of
    ``cfg.checkpoint_freq`` env steps (counted over the whole run, so a resumed run keeps the
    schedule): with ``normalize`` the observation statistics, for SAC the replay buffer, then the
    model (:func:`~sms3d_env.training.actor.checkpoint_path` names them), each atomically. The
    model comes last: a checkpoint whose model is on disk is complete."""
    from stable_baselines3.common.callbacks import BaseCallback

    freq = cfg.checkpoint_freq

    class _Checkpoints(BaseCallback):
        def _on_training_start(self) -> None:
            self.next_at = (self.model.num_timesteps // freq + 1) * freq

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next_at:
                self.next_at = (self.num_timesteps // freq + 1) * freq
                folder.mkdir(parents=True, exist_ok=True)
                if cfg.algo == "sac":
                    save_replay_buffer(self.model.replay_buffer,
                                       checkpoint_path(folder, cfg.algo, self.num_timesteps, "replay_buffer"))
                _save_model_and_stats(self.model, env, cfg.normalize,
                                      checkpoint_path(folder, cfg.algo, self.num_timesteps),
                                      checkpoint_path(folder, cfg.algo, self.num_timesteps, "obs_rms"))
            return True

    return _Checkpoints()


def _checkpoint_parts(cfg: TrainConfig) -> list[str]:
    """What a checkpoint of ``cfg``'s run holds (keys of :data:`~sms3d_env.training.actor.CHECKPOINT_PARTS`)."""
    return ["model"] + (["obs_rms"] if cfg.normalize else []) + (["replay_buffer"] if cfg.algo == "sac" else [])


def latest_checkpoint(folder: Path, cfg: TrainConfig) -> Path | None:
    """The model of the checkpoint in ``folder`` with the most steps whose parts are all there;
    None when there is none. ``PolicyFileError`` when the latest SAC checkpoint's replay buffer
    is SB3's pickle (``sac_replay_buffer_<N>_steps.pkl``, written by earlier versions), which is
    not loaded: unpickling runs code from the file, and starting over would drop the run."""
    steps = sorted({n for p in folder.glob(f"{cfg.algo}_*_steps.zip") if (n := checkpoint_steps(p)) is not None},
                   reverse=True)
    for n in steps:
        if all(checkpoint_path(folder, cfg.algo, n, part).is_file() for part in _checkpoint_parts(cfg)):
            return checkpoint_path(folder, cfg.algo, n)
        pickled = checkpoint_path(folder, cfg.algo, n, "replay_buffer").with_suffix(".pkl")
        if cfg.algo == "sac" and pickled.is_file():
            raise PolicyFileError(pickled, "the replay buffer is an SB3 pickle, which is not loaded (unpickling runs "
                                           "code from the file); --overwrite to start the run anew")
    return None


def _resume_from(checkpoint: Path, env: Any, cfg: TrainConfig) -> Any:
    """The run's model at ``checkpoint`` with what SB3 saves of its training state (weights,
    optimiser, step count), its observation statistics in ``env`` and, for SAC, its replay
    buffer; nothing is unpickled. The policy, spaces and schedules that SB3 pickled in the
    checkpoint are rebuilt from the run's settings and env (:func:`_model_arguments`); the last
    observations it pickled are of envs that are gone, and the resumed run resets its own."""
    policy, kwargs = _model_arguments(cfg)
    spec = PolicySpec(cfg.algo, policy, env.observation_space, env.action_space)
    model = load_sb3(checkpoint, (cfg.algo,), spec, hyperparameters=kwargs, env=env, device=cfg.device)
    steps = checkpoint_steps(checkpoint)
    if cfg.normalize:
        ObservationStats.load(checkpoint_path(checkpoint.parent, cfg.algo, steps, "obs_rms")).apply_to(env)
    if cfg.algo == "sac":
        load_replay_buffer(model.replay_buffer, checkpoint_path(checkpoint.parent, cfg.algo, steps, "replay_buffer"))
    return model


def _rows_until(path: Path, steps: int) -> list[str]:
    """The lines of SB3's CSV log ``path`` (header first) whose ``time/total_timesteps`` is at most
    ``steps``: what a run resumed from its checkpoint at ``steps`` keeps (later rows logged
    training that it redoes). A last line without its newline, cut by a kill, is dropped."""
    lines = path.read_text().splitlines(keepends=True) if path.is_file() else []
    if lines and not lines[-1].endswith("\n"):
        lines.pop()
    if not lines:
        return []
    header = next(csv.reader([lines[0]]))
    if "time/total_timesteps" not in header:
        return lines
    col = header.index("time/total_timesteps")

    def before(line: str) -> bool:
        value = next(csv.reader([line]))[col:col + 1]
        return not value or not value[0] or float(value[0]) <= steps

    return [lines[0], *filter(before, lines[1:])]


def _progress_csv(path: Path, resumed_at: int | None) -> Any:
    """SB3's CSV log format writing ``path``: a new file, or for a run resumed at step
    ``resumed_at`` the kept rows (:func:`_rows_until`) continued under their header."""
    from stable_baselines3.common.logger import CSVOutputFormat

    if resumed_at is None:
        return CSVOutputFormat(str(path))

    class _ContinuedCSV(CSVOutputFormat):
        def __init__(self) -> None:
            # Not CSVOutputFormat.__init__, which truncates the file. "r+", not "a": on new keys
            # the format rewrites the file from its start.
            kept = _rows_until(path, resumed_at)
            write_atomic(path, "".join(kept))
            self.file = open(path, "r+")  # noqa: SIM115  (closed by the logger)
            self.file.seek(0, os.SEEK_END)
            self.keys = kept[0].rstrip("\n").split(",") if kept else []
            self.separator, self.quotechar = ",", '"'

    return _ContinuedCSV()


def _evaluation(eval_env: Any, env: Any, out: Path, cfg: TrainConfig, resumed_at: int | None) -> Any:
    """SB3's ``EvalCallback`` writing ``eval/evaluations.npz`` atomically, saving the best model
    through :func:`_save_best`, and for a run resumed at step ``resumed_at`` continuing the
    evaluations up to that step and their best mean reward."""
    from stable_baselines3.common.callbacks import EvalCallback

    final = out / "eval" / "evaluations.npz"

    class _Evaluation(EvalCallback):
        def __init__(self) -> None:
            super().__init__(eval_env, n_eval_episodes=cfg.eval_episodes,
                             eval_freq=max(cfg.eval_freq // cfg.n_envs, 1), log_path=str(final.parent),
                             callback_on_new_best=_save_best(env, out, cfg.normalize),
                             deterministic=True, verbose=cfg.verbose, warn=False)
            # SB3 writes its np.savez in place; it writes here (adding .npz), renamed into place after.
            self.log_path = str(final.with_name("evaluations.tmp"))
            if resumed_at is not None and final.is_file():
                self._continue(resumed_at)

        def _continue(self, steps: int) -> None:
            with np.load(final, allow_pickle=False) as saved:
                keep = saved["timesteps"] <= steps
                self.evaluations_timesteps = saved["timesteps"][keep].tolist()
                self.evaluations_results = saved["results"][keep].tolist()
                self.evaluations_length = saved["ep_lengths"][keep].tolist()
                if "successes" in saved.files:
                    self.evaluations_successes = saved["successes"][keep].tolist()
                means = np.mean(saved["results"], axis=1)
            if len(means) and not keep[int(np.argmax(means))]:
                # best/ holds a model of the training this run redoes: not this run's best. The
                # next evaluation saves one again.
                shutil.rmtree(out / "best", ignore_errors=True)
            elif self.evaluations_results:
                self.best_mean_reward = float(np.max(means[keep]))

        def _on_step(self) -> bool:
            go_on = super()._on_step()
            written = Path(f"{self.log_path}.npz")
            if written.is_file():
                os.replace(written, final)
            return go_on

    return _Evaluation()


def wall_clock_limit(max_wall_s: float) -> Any:
    """An SB3 callback that stops training once ``max_wall_s`` seconds have passed since it began
    (``TrainConfig.max_wall_s``; an RL Zoo recipe names it as a ``callback``)."""
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
    from sms3d_env.policies.envs import make_env

    env = make_env(**{**cfg.env_kwargs(), "flat_observation": False})
    try:
        return list(env.observation_space.spaces)
    finally:
        env.close()


#: ``TrainConfig`` fields that say how a run is carried out, not what it computes: a resumed run
#: may take other values.
RUN_ONLY_FIELDS = ("verbose", "device", "torch_threads")


def train_policy(cfg: TrainConfig, overwrite: bool = False) -> dict[str, Any]:
    """Train, log and save a policy; returns a summary (also written to ``out/summary.json``).

    Files in ``cfg.out``: ``model.zip`` (final), ``config.json``, ``summary.json``,
    ``progress.csv`` (SB3 logger; ``eval/success_rate`` rows after each evaluation),
    TensorBoard events if ``tensorboard`` is installed, ``checkpoints/``, ``best/best_model.zip``,
    ``eval/evaluations.npz``, ``monitor/`` (per-episode return, length, is_success) and, with
    ``normalize``, ``obs_rms.npz`` beside each model.

    ``cfg.out`` is a run folder (:func:`generator.run_folder.open_run_folder`), opened once every
    input is checked (``InitModelError``, ``RunFolderError``, ``PolicyFileError``: nothing is
    written before). A rerun with the same settings (``RUN_ONLY_FIELDS`` aside) resumes from the
    latest complete checkpoint, printing ``resuming OUT from step N of M``: SB3's saved training
    state, the observation statistics and SAC's replay buffer; ``progress.csv`` and
    ``eval/evaluations.npz`` keep their rows up to step N, ``monitor/`` every episode. Its
    ``max_wall_s`` counts from its own start. A finished run (``summary.json``) says so and
    returns its summary. Other settings are refused naming them, unless ``overwrite``, which
    empties the folder first.
    """
    from sms3d_env.training.threads import torch_threads

    # A SubprocVecEnv for training and a DummyVecEnv for evaluation is intended here.
    warnings.filterwarnings("ignore", message="Training and eval env are not of the same type")

    with torch_threads(cfg.torch_threads):
        return _train(cfg, overwrite)


def _train(cfg: TrainConfig, overwrite: bool) -> dict[str, Any]:
    from stable_baselines3.common.callbacks import CallbackList
    from stable_baselines3.common.logger import configure

    if cfg.init_model is not None:
        _check_init_model_fits(cfg)
    saved = {"recipe": "rl", **asdict(cfg),
             "env_options": env_options(cfg.posture_target)}
    if cfg.flat_observation:
        saved["observation_keys"] = _observation_keys(cfg)
    run = open_run_folder(cfg.out, run_settings(saved), overwrite=overwrite, may_change=RUN_ONLY_FIELDS)
    with run:  # holds the folder's lock until the run ends
        out = run.path
        finished = finished_run(out) if run.resumed else None
        if finished is not None:
            return finished
        run.check_writable()
        write_atomic(out / "config.json", json.dumps(saved, indent=2))
        checkpoint = latest_checkpoint(out / "checkpoints", cfg) if run.resumed else None
        start = 0 if checkpoint is None else checkpoint_steps(checkpoint)
        if run.resumed:
            print(f"resuming {out} from step {start} of {cfg.total_steps}"
                  + ("" if checkpoint else " (no complete checkpoint yet)"))
        env = vec_env(cfg.env_kwargs(), cfg.n_envs, cfg.seed, str(out / "monitor"), cfg.vec_env,
                      continue_monitor=run.resumed)
        if cfg.normalize:
            env = normalized(env, training=True, reward_gamma=cfg.gamma if cfg.normalize_reward else None)
        eval_env = None
        try:
            if checkpoint is not None:
                model = _resume_from(checkpoint, env, cfg)
            else:
                model = _build_model(cfg, env)
                if cfg.init_model is not None:
                    _start_from(model, env, cfg)
            formats = (["stdout"] if cfg.verbose else []) + (["tensorboard"] if _tensorboard_available() else [])
            logger = configure(str(out), formats)
            logger.output_formats.append(_progress_csv(out / "progress.csv", start if run.resumed else None))
            model.set_logger(logger)
            callbacks: list[Any] = []
            if cfg.eval_freq > 0:
                # Periodic evaluation under the training pose condition (fixed seeds): fresh beds, not
                # the training pool's, and every episode from home.
                eval_env = vec_env(cfg.env_kwargs(evaluation=True), 1, cfg.seed + 10_000, None)
                if cfg.normalize:
                    # EvalCallback copies the training statistics into it before each evaluation.
                    eval_env = normalized(eval_env, training=False)
                callbacks.append(_evaluation(eval_env, env, out, cfg, start if run.resumed else None))
            if cfg.checkpoint_freq > 0:
                callbacks.append(_checkpoints(env, out / "checkpoints", cfg))
            if cfg.pregrasp_anneal:
                callbacks.append(pregrasp_annealing(cfg.pregrasp_start))
            if cfg.max_wall_s is not None:
                callbacks.append(wall_clock_limit(cfg.max_wall_s))
            t0 = time.perf_counter()
            # SB3 adds the steps already made to total_timesteps, so schedules run over the whole run.
            model.learn(total_timesteps=cfg.total_steps - start, callback=CallbackList(callbacks),
                        reset_num_timesteps=checkpoint is None, progress_bar=False)
            wall = time.perf_counter() - t0
            _save_model_and_stats(model, env, cfg.normalize, out / "model.zip", out / OBS_STATS_FILE)
            steps = int(model.num_timesteps) - start
            summary = {
                "algo": cfg.algo, "steps": int(model.num_timesteps), "resumed_from_step": start, "wall_s": round(wall, 1),
                "steps_per_s": round(steps / wall, 1) if wall > 0 else math.nan,
                "n_envs": cfg.n_envs, "pose_source": cfg.pose_source, "pose_error_deg": cfg.pose_error_deg,
                "model": str(out / "model.zip"), "tensorboard": "tensorboard" in formats,
            }
            write_atomic(out / "summary.json", json.dumps(summary, indent=2))
            return summary
        finally:
            env.close()
            if eval_env is not None:
                eval_env.close()
