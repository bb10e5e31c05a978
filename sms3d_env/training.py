"""Pick policies trained with stable-baselines3 (PPO or SAC) on ``SMS3DPick-v0`` or on the
learnable options of ``SMS3DPickTrain-v0``.

``train_policy(TrainConfig(...))`` trains with vectorised envs (``SubprocVecEnv`` for
``n_envs > 1``), evaluates periodically (``eval/success_rate`` from the env's ``is_success``),
writes CSV (and TensorBoard, if installed) logs, checkpoints and ``model.zip`` plus
``config.json`` and ``summary.json`` into ``out``; ``normalize=True`` standardises observations
(SB3's ``VecNormalize``, saved as ``vecnormalize.pkl`` beside the model). The demonstration-started
recipe lives in :mod:`sms3d_env.imitation`. ``evaluate_policy_success`` runs a saved model (by
default the shipped policy, ``SHIPPED_POLICY``) for seeded episodes under the env id and options
it was trained with and returns the success rate with a 95 % Wilson interval and the failure
causes. ``register`` adds ``sms3d train-policy`` and ``sms3d eval-policy``.
"""

from __future__ import annotations

import functools
import json
import math
import time
import warnings
from collections import Counter
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

ALGOS = ("ppo", "sac")
POSE_SOURCES = ("oracle", "noisy")
REWARD_TYPES = ("dense", "sparse", "staged")
ENV_IDS = ("SMS3DPick-v0", "SMS3DPickTrain-v0")
RECIPES = ("rl", "bc", "residual")
#: The shipped pick policy (``model.zip`` with its ``config.json``, ``README.md``, metrics).
SHIPPED_POLICY = Path(__file__).parent / "weights" / "pick_policy" / "model.zip"
VECNORM_FILE = "vecnormalize.pkl"


def _tensorboard_available() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run depends on (saved as ``config.json`` next to the model).

    Args:
        algo: ``"ppo"`` or ``"sac"``.
        total_steps: environment steps over all envs.
        max_wall_s: stop early (after the current step) once this many seconds have passed.
        n_envs: parallel envs (``SubprocVecEnv`` if > 1, else ``DummyVecEnv``).
        pose_source, pose_error_deg, position_noise: the target pose estimate used in training.
        env_id: ``"SMS3DPick-v0"`` (its options as given here) or ``"SMS3DPickTrain-v0"`` (the
            learnable options: latched suction, staged reward, dead-end episode end, task
            observations; ``reward_type`` is then ignored and must stay at its default).
        normalize: standardise observations with running statistics (``VecNormalize``).
        scene_pool: > 0: each env draws its beds from a pool of this many (the env's
            ``scene_pool``; resets then cost physics, not placement and compilation).
        residual_scale: > 0 trains a residual on top of the scripted picker
            (:class:`sms3d_env.residual.ResidualPicker` with this scale); 0: the policy acts alone.
        pose_error_range_deg: ``(low, high)``: train under a pose error drawn per episode
            uniformly in that range (``pose_source`` must then be ``"noisy"`` and
            ``pose_error_deg`` 0).
        reward_type: ``"dense"``, ``"sparse"`` or ``"staged"``.
        num_mushrooms: mushrooms per generated scene.
        max_episode_steps: episode limit (the registered env uses 250).
        eval_freq, checkpoint_freq: in total env steps; 0 disables.
        eval_episodes: episodes per periodic evaluation (oracle poses, same scenes per eval).
        learning_rate, batch_size, n_steps (PPO, per env), buffer_size and learning_starts (SAC),
        gamma, net_arch: algorithm hyper-parameters.
        log_std_init: the Gaussian policy's initial log standard deviation (SB3's default 0: a
            standard deviation of 1 on every normalised command; a residual starts quieter).
        torch_threads: ``torch.set_num_threads`` in the training process. 1 by default: the
            policy's per-step forward pass is tiny, and with the env workers (and anything else)
            on the same cores, 2 intra-op threads made it ~50x slower here (64 ms vs 1.2 ms).
    """

    algo: str = "ppo"
    env_id: str = "SMS3DPick-v0"
    normalize: bool = False
    scene_pool: int = 0
    residual_scale: float = 0.0
    pose_error_range_deg: tuple[float, float] | None = None
    total_steps: int = 100_000
    max_wall_s: float | None = None
    n_envs: int = 1
    pose_source: str = "oracle"
    pose_error_deg: float = 0.0
    position_noise: float = 0.0
    reward_type: str = "dense"
    num_mushrooms: int = 10
    max_episode_steps: int = 250
    seed: int = 0
    out: str = "runs/policy"
    eval_freq: int = 20_000
    eval_episodes: int = 10
    checkpoint_freq: int = 50_000
    learning_rate: float = 3e-4
    batch_size: int = 256
    n_steps: int = 1024
    buffer_size: int = 100_000
    learning_starts: int = 1_000
    gamma: float = 0.99
    net_arch: tuple[int, ...] = (256, 256)
    log_std_init: float = 0.0
    device: str = "cpu"
    torch_threads: int = 1
    verbose: int = 1

    def __post_init__(self) -> None:
        def bad(name: str, why: str) -> ValueError:
            return ValueError(f"TrainConfig.{name} {why}, got {getattr(self, name)!r}")

        if self.algo not in ALGOS:
            raise bad("algo", f"must be one of {ALGOS}")
        if self.pose_source not in POSE_SOURCES:
            raise bad("pose_source", f"must be one of {POSE_SOURCES}")
        if self.reward_type not in REWARD_TYPES:
            raise bad("reward_type", f"must be one of {REWARD_TYPES}")
        if self.env_id not in ENV_IDS:
            raise bad("env_id", f"must be one of {ENV_IDS}")
        if self.env_id == "SMS3DPickTrain-v0" and self.reward_type != "dense":
            raise bad("reward_type", "is set by SMS3DPickTrain-v0 (staged); leave it at its default")
        if not isinstance(self.normalize, bool):
            raise bad("normalize", "must be a bool")
        if not (isinstance(self.residual_scale, (int, float)) and math.isfinite(self.residual_scale)
                and 0 <= self.residual_scale <= 2):
            raise bad("residual_scale", "must be a number in [0, 2]")
        if self.pose_error_range_deg is not None:
            rng = tuple(float(v) for v in self.pose_error_range_deg)
            if len(rng) != 2 or not all(math.isfinite(v) for v in rng) or not 0 <= rng[0] <= rng[1] <= 180:
                raise bad("pose_error_range_deg", "must be (low, high) with 0 <= low <= high <= 180")
            if self.pose_source != "noisy" or self.pose_error_deg:
                raise bad("pose_error_range_deg", "needs pose_source='noisy' and pose_error_deg=0")
            object.__setattr__(self, "pose_error_range_deg", rng)
        for name in ("total_steps", "n_envs", "torch_threads", "num_mushrooms", "max_episode_steps", "eval_episodes",
                     "batch_size", "n_steps", "buffer_size"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise bad(name, "must be an integer >= 1")
        for name in ("eval_freq", "checkpoint_freq", "learning_starts", "seed", "verbose", "scene_pool"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise bad(name, "must be an integer >= 0")
        for name in ("pose_error_deg", "position_noise"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise bad(name, "must be a finite number >= 0")
        if self.pose_source == "oracle" and (self.pose_error_deg > 0 or self.position_noise > 0):
            raise bad("pose_error_deg", "must be 0 with pose_source='oracle' (use 'noisy')")
        if self.max_wall_s is not None and not (math.isfinite(self.max_wall_s) and self.max_wall_s > 0):
            raise bad("max_wall_s", "must be None or a finite number > 0")
        if not (isinstance(self.learning_rate, (int, float)) and 0 < self.learning_rate < 1):
            raise bad("learning_rate", "must be in (0, 1)")
        if not (0 < self.gamma <= 1):
            raise bad("gamma", "must be in (0, 1]")
        if len(self.net_arch) == 0 or any(int(h) < 1 for h in self.net_arch):
            raise bad("net_arch", "must be a non-empty sequence of positive layer widths")
        if not (isinstance(self.log_std_init, (int, float)) and math.isfinite(self.log_std_init)):
            raise bad("log_std_init", "must be a finite number")
        if not self.out:
            raise bad("out", "must be a non-empty path")
        object.__setattr__(self, "net_arch", tuple(int(h) for h in self.net_arch))

    def env_kwargs(self, pose_source: str | None = None, pose_error_deg: float | None = None) -> dict[str, Any]:
        kw = env_kwargs(self.num_mushrooms, pose_source or self.pose_source,
                        self.pose_error_deg if pose_error_deg is None else pose_error_deg,
                        self.position_noise, self.reward_type, self.max_episode_steps)
        if self.env_id != "SMS3DPick-v0":
            kw.pop("reward_type")  # the training id sets its own
        if self.pose_error_range_deg is not None and pose_error_deg is None:
            from sms3d_env.pose_source import UniformNoisyPose

            kw.pop("pose_error_deg")
            kw["pose_source"] = UniformNoisyPose(*self.pose_error_range_deg)
        if self.scene_pool:
            kw["scene_pool"] = self.scene_pool
        return {"env_id": self.env_id, "residual_scale": self.residual_scale, **kw}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        known = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in known}
        if "net_arch" in kw:
            kw["net_arch"] = tuple(kw["net_arch"])
        return cls(**kw)


def env_kwargs(num_mushrooms: int, pose_source: str, pose_error_deg: float, position_noise: float = 0.0,
               reward_type: str = "dense", max_episode_steps: int = 250) -> dict[str, Any]:
    import generator

    kw = {
        "scene_config": generator.SceneConfig().replace(placement__num_mushrooms=int(num_mushrooms)),
        "pose_source": pose_source, "reward_type": reward_type,
        "max_episode_steps": int(max_episode_steps),
    }
    if pose_source == "noisy":  # the env refuses pose errors it would ignore
        kw.update(pose_error_deg=float(pose_error_deg), position_noise=float(position_noise))
    return kw


def _make_env(env_id: str = "SMS3DPick-v0", residual_scale: float = 0.0, **kwargs: Any) -> Any:
    """Module-level factory so that ``SubprocVecEnv`` workers can unpickle it; ``residual_scale``
    > 0 wraps the env in a ``ResidualPicker``."""
    import gymnasium as gym

    import sms3d_env  # noqa: F401  (registers the env ids)

    env = gym.make(env_id, **kwargs)
    if residual_scale > 0:
        from sms3d_env.residual import ResidualPicker

        env = ResidualPicker(env, residual_scale)
    return env


def _vec_env(kwargs: dict[str, Any], n_envs: int, seed: int, monitor_dir: str | None) -> Any:
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    return make_vec_env(functools.partial(_make_env, **kwargs), n_envs=n_envs, seed=seed,
                        monitor_dir=monitor_dir,
                        vec_env_cls=SubprocVecEnv if n_envs > 1 else DummyVecEnv,
                        monitor_kwargs={"info_keywords": ("is_success", "failure_cause")})


def _normalized(env: Any, training: bool) -> Any:
    """Observations standardised by running statistics (rewards as they are: the staged reward
    is bounded already, and evaluation reports true returns)."""
    from stable_baselines3.common.vec_env import VecNormalize

    return VecNormalize(env, norm_obs=True, norm_reward=False, training=training)


def _build_model(cfg: TrainConfig, env: Any) -> Any:
    from stable_baselines3 import PPO, SAC

    policy_kwargs = {"net_arch": list(cfg.net_arch), "log_std_init": float(cfg.log_std_init)}
    if cfg.algo == "ppo":
        n_steps = cfg.n_steps
        batch = min(cfg.batch_size, n_steps * cfg.n_envs)
        return PPO("MultiInputPolicy", env, learning_rate=cfg.learning_rate, n_steps=n_steps,
                   batch_size=batch, gamma=cfg.gamma, policy_kwargs=policy_kwargs, seed=cfg.seed,
                   device=cfg.device, verbose=cfg.verbose)
    return SAC("MultiInputPolicy", env, learning_rate=cfg.learning_rate, buffer_size=cfg.buffer_size,
               learning_starts=cfg.learning_starts, batch_size=cfg.batch_size, gamma=cfg.gamma,
               policy_kwargs=policy_kwargs, seed=cfg.seed, device=cfg.device, verbose=cfg.verbose)


def _wall_clock_callback(max_wall_s: float) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class _StopAfter(BaseCallback):
        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter()

        def _on_step(self) -> bool:
            return time.perf_counter() - self.t0 < max_wall_s

    return _StopAfter()


def train_policy(cfg: TrainConfig) -> dict[str, Any]:
    """Train, log and save a policy; returns a summary (also written to ``out/summary.json``).

    Files in ``cfg.out``: ``model.zip`` (final), ``config.json``, ``summary.json``,
    ``progress.csv`` (SB3 logger; ``eval/success_rate`` rows after each evaluation),
    TensorBoard events if ``tensorboard`` is installed, ``checkpoints/``, ``best/best_model.zip``,
    ``eval/evaluations.npz`` and ``monitor/`` (per-episode return, length, is_success).
    """
    import torch

    # A SubprocVecEnv for training and a DummyVecEnv for evaluation is intended here.
    warnings.filterwarnings("ignore", message="Training and eval env are not of the same type")

    threads = torch.get_num_threads()
    torch.set_num_threads(cfg.torch_threads)
    try:
        return _train(cfg)
    finally:
        torch.set_num_threads(threads)


def _train(cfg: TrainConfig) -> dict[str, Any]:
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback, EvalCallback
    from stable_baselines3.common.logger import configure

    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(asdict(cfg), indent=2))
    env = _vec_env(cfg.env_kwargs(), cfg.n_envs, cfg.seed, str(out / "monitor"))
    if cfg.normalize:
        env = _normalized(env, training=True)
    eval_env = None
    try:
        model = _build_model(cfg, env)
        formats = ["stdout", "csv"] + (["tensorboard"] if _tensorboard_available() else [])
        if not cfg.verbose:
            formats.remove("stdout")
        model.set_logger(configure(str(out), formats))
        callbacks: list[Any] = []
        if cfg.eval_freq > 0:
            # Periodic evaluation under the training pose condition (fixed seeds).
            # Fresh beds, not the training pool's.
            eval_kw = {k: v for k, v in cfg.env_kwargs().items() if k != "scene_pool"}
            eval_env = _vec_env(eval_kw, 1, cfg.seed + 10_000, None)
            if cfg.normalize:
                # EvalCallback copies the training statistics into it before each evaluation.
                eval_env = _normalized(eval_env, training=False)
            callbacks.append(EvalCallback(
                eval_env, n_eval_episodes=cfg.eval_episodes, eval_freq=max(cfg.eval_freq // cfg.n_envs, 1),
                log_path=str(out / "eval"), best_model_save_path=str(out / "best"),
                deterministic=True, verbose=cfg.verbose, warn=False))
        if cfg.checkpoint_freq > 0:
            callbacks.append(CheckpointCallback(max(cfg.checkpoint_freq // cfg.n_envs, 1),
                                                str(out / "checkpoints"), name_prefix=cfg.algo,
                                                save_vecnormalize=cfg.normalize))
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


def evaluate_policy_success(model_path: str | Path | None = None, episodes: int = 30,
                            pose_error_deg: float = 0.0, seed: int = 0,
                            num_mushrooms: int | None = None,
                            max_episode_steps: int | None = None, algo: str | None = None,
                            deterministic: bool = True, progress: bool = False) -> dict[str, Any]:
    """Success of a saved policy over seeded episodes with oracle (0 deg) or noisy target poses.

    ``model_path`` None: the shipped policy. The env is the id and options the policy was trained
    with (``config.json`` beside the model) on ``num_mushrooms``-mushroom beds (default: the
    single bed size it was trained on, else 25, the registered env's — so the shipped policy,
    trained on 10 and 25, is evaluated on 25). Episode ``i`` uses ``reset(seed=seed + i)``, so the scenes are the same for
    every model and pose error.

    Returns ``{"episodes", "successes", "success_rate", "ci95": (lo, hi), "reachable",
    "success_rate_reachable", "failure_causes": {cause: count}, "target_detached_at_end",
    "target_held_at_end" (episode counts), "mean_return", "mean_steps", "per_episode" (success
    per episode), "env_id", "env_options", "num_mushrooms", "pose_error_deg", "seed", "model"}``.
    """
    from tqdm import tqdm

    from sms3d_env.study_report import wilson_interval

    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be an integer >= 1, got {episodes!r}")
    if not (math.isfinite(pose_error_deg) and pose_error_deg >= 0):
        raise ValueError(f"pose_error_deg must be a finite number >= 0, got {pose_error_deg!r}")
    if num_mushrooms is not None and (isinstance(num_mushrooms, bool) or not isinstance(num_mushrooms, int)
                                      or num_mushrooms < 1):
        raise ValueError(f"num_mushrooms must be an integer >= 1, got {num_mushrooms!r}")
    actor = PolicyActor(SHIPPED_POLICY if model_path is None else model_path, algo, deterministic)
    trained_on = actor.saved.get("num_mushrooms")
    num_mushrooms = num_mushrooms or (trained_on if isinstance(trained_on, int) else 25)
    kw = env_kwargs(num_mushrooms, "noisy" if pose_error_deg > 0 else "oracle", pose_error_deg,
                    0.0, actor.saved.get("reward_type", "dense"),
                    max_episode_steps or actor.saved.get("max_episode_steps", 250))
    if actor.env_id != "SMS3DPick-v0":
        kw.pop("reward_type")
    kw.update(actor.env_options)
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # per-step inference of a small MLP: more threads only add overhead
    env = _make_env(actor.env_id, actor.residual_scale, **kw)
    causes: Counter[str] = Counter()
    successes = reachable = reach_succ = detached = held = 0
    returns, lengths, per_episode = [], [], []
    try:
        for i in tqdm(range(episodes), desc="eval-policy", disable=not progress, unit="ep"):
            obs, info = env.reset(seed=seed + i)
            done, total, steps = False, 0.0, 0
            while not done:
                obs, reward, terminated, truncated, info = env.step(actor(obs))
                total += float(reward)
                steps += 1
                done = terminated or truncated
            ok = bool(info["is_success"])
            successes += ok
            per_episode.append(ok)
            reachable += bool(info["reachable"])
            reach_succ += ok and bool(info["reachable"])
            detached += bool(info["target_detached"])
            held += bool(info["gripped_target"])
            if not ok:
                causes[str(info["failure_cause"])] += 1
            returns.append(total)
            lengths.append(steps)
    finally:
        env.close()
        torch.set_num_threads(threads)
    lo, hi = wilson_interval(successes, episodes)
    return {
        "model": str(actor.path), "episodes": episodes, "successes": successes,
        "success_rate": successes / episodes, "ci95": (lo, hi), "reachable": reachable,
        "success_rate_reachable": reach_succ / reachable if reachable else math.nan,
        "failure_causes": dict(sorted(causes.items())),
        "target_detached_at_end": detached, "target_held_at_end": held, "mean_return": float(np.mean(returns)),
        "mean_steps": float(np.mean(lengths)), "per_episode": per_episode, "env_id": actor.env_id,
        "env_options": actor.env_options, "num_mushrooms": num_mushrooms,
        "pose_error_deg": float(pose_error_deg), "seed": seed,
    }


def success_line(res: dict[str, Any]) -> str:
    """``success K/N (P %, 95 % CI lo-hi %); failures: cause n, ...`` of an evaluation result."""
    lo, hi = res["ci95"]
    causes = ", ".join(f"{c} {n}" for c, n in res["failure_causes"].items()) or "none"
    return (f"success {res['successes']}/{res['episodes']} ({100 * res['success_rate']:.1f} %, "
            f"95 % CI {100 * lo:.1f}-{100 * hi:.1f} %); failures: {causes}")


# ---------------------------------------------------------------------------------- CLI
def _cmd_train(args: Any) -> int:
    if args.recipe == "bc":
        return _cmd_train_bc(args)
    noisy = args.pose_error_deg > 0 or args.pose_error_range is not None
    pose_source = args.pose_source or ("noisy" if noisy else "oracle")
    residual = args.recipe == "residual"
    try:
        cfg = TrainConfig(algo=args.algo, env_id="SMS3DPickTrain-v0" if residual else args.env_id,
                          normalize=args.normalize or residual, scene_pool=args.scene_pool,
                          residual_scale=args.residual_scale if residual else 0.0,
                          pose_error_range_deg=args.pose_error_range,
                          log_std_init=args.log_std_init if args.log_std_init is not None
                          else (-1.6 if residual else 0.0),
                          total_steps=args.steps, max_wall_s=args.max_wall_s,
                          n_envs=args.n_envs, pose_source=pose_source, pose_error_deg=args.pose_error_deg,
                          reward_type=args.reward_type, num_mushrooms=args.num_mushrooms, seed=args.seed,
                          out=args.out, eval_freq=args.eval_freq, eval_episodes=args.eval_episodes,
                          checkpoint_freq=args.checkpoint_freq)
    except ValueError as e:
        print(f"error: {e}")
        return 2
    summary = train_policy(cfg)
    print(json.dumps(summary, indent=2))
    return 0


def _cmd_train_bc(args: Any) -> int:
    from sms3d_env.imitation import BCConfig, train_bc

    try:
        cfg = BCConfig(episodes=args.demo_episodes, epochs=args.epochs, action_noise=args.action_noise,
                       pose_error_deg=args.pose_error_deg, seed=args.seed, out=args.out,
                       num_mushrooms=tuple(args.demo_mushrooms), dagger_rounds=args.dagger_rounds,
                       dagger_episodes=args.dagger_episodes)
    except ValueError as e:
        print(f"error: {e}")
        return 2
    print(json.dumps(train_bc(cfg), indent=2))
    return 0


def _cmd_eval(args: Any) -> int:
    try:
        res = evaluate_policy_success(args.model, episodes=args.episodes, pose_error_deg=args.pose_error_deg,
                                      seed=args.seed, num_mushrooms=args.num_mushrooms, progress=True)
    except (ValueError, FileNotFoundError) as e:
        print(f"error: {e}")
        return 2
    text = json.dumps({k: v for k, v in res.items() if k != "per_episode"}, indent=2)
    print(text)
    print(success_line(res))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(res, indent=2))
    return 0


def register(subparsers: Any) -> None:
    """Add ``sms3d train-policy``, ``sms3d eval-policy`` and ``sms3d learning-curve``."""
    defaults = TrainConfig()
    p = subparsers.add_parser(
        "train-policy", help="train a pick policy: RL (PPO/SAC, stable-baselines3) or behaviour "
                             "cloning of the scripted picker (--recipe bc)")
    p.add_argument("--recipe", choices=RECIPES, default="rl",
                   help="rl: PPO/SAC from scratch (default); bc: scripted demonstrations -> "
                        "behaviour cloning on SMS3DPickTrain-v0 (sms3d_env.imitation); residual: "
                        "PPO/SAC on top of the scripted picker on SMS3DPickTrain-v0 (sms3d_env.residual)")
    p.add_argument("--algo", choices=ALGOS, default=defaults.algo)
    p.add_argument("--env-id", choices=ENV_IDS, default=defaults.env_id,
                   help="SMS3DPickTrain-v0: the learnable options (latched suction, staged reward, ...)")
    p.add_argument("--normalize", action="store_true", help="standardise observations (VecNormalize)")
    p.add_argument("--scene-pool", type=int, default=defaults.scene_pool,
                   help="draw training beds from a pool of this many (0: a new bed per reset)")
    p.add_argument("--steps", type=int, default=defaults.total_steps, help="total env steps")
    p.add_argument("--max-wall-s", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--n-envs", type=int, default=defaults.n_envs, help="parallel envs (SubprocVecEnv if > 1)")
    p.add_argument("--pose-source", choices=POSE_SOURCES, default=None,
                   help="default: noisy if --pose-error-deg > 0, else oracle")
    p.add_argument("--pose-error-deg", type=float, default=0.0)
    p.add_argument("--pose-error-range", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="train under a pose error drawn per episode in [LOW, HIGH] degrees")
    p.add_argument("--residual-scale", type=float, default=0.5,
                   help="--recipe residual: the residual's largest share of each command")
    p.add_argument("--log-std-init", type=float, default=None,
                   help="initial log standard deviation of the policy (default 0; -1.6 for --recipe residual)")
    p.add_argument("--reward-type", choices=REWARD_TYPES, default=defaults.reward_type)
    p.add_argument("--out", default=defaults.out, help="run folder (model.zip, progress.csv, ...)")
    p.add_argument("--seed", type=int, default=defaults.seed)
    p.add_argument("--num-mushrooms", type=int, default=defaults.num_mushrooms)
    p.add_argument("--eval-episodes", type=int, default=defaults.eval_episodes,
                   help="episodes per periodic evaluation")
    p.add_argument("--eval-freq", type=int, default=defaults.eval_freq, help="env steps between evaluations (0: none)")
    p.add_argument("--checkpoint-freq", type=int, default=defaults.checkpoint_freq,
                   help="env steps between checkpoints (0: none)")
    bc = p.add_argument_group("behaviour cloning (--recipe bc)")
    bc.add_argument("--demo-episodes", type=int, default=400, help="scripted episodes (failures dropped)")
    bc.add_argument("--demo-mushrooms", type=int, nargs="+", default=[10, 25], help="bed sizes cycled through")
    bc.add_argument("--action-noise", type=float, default=0.2, help="DART noise on the twist while collecting")
    bc.add_argument("--epochs", type=int, default=40, help="epochs of the first clone")
    bc.add_argument("--dagger-rounds", type=int, default=3, help="DAgger rounds after it (0: plain BC)")
    bc.add_argument("--dagger-episodes", type=int, default=150, help="episodes per DAgger round")
    p.set_defaults(func=_cmd_train)

    e = subparsers.add_parser("eval-policy", help="success rate (95 %% Wilson interval) of a saved policy "
                                                  "(default: the shipped one)")
    e.add_argument("--model", default=None, help="path to model.zip (default: the shipped policy)")
    e.add_argument("--episodes", "--eval-episodes", dest="episodes", type=int, default=30)
    e.add_argument("--pose-error-deg", type=float, default=0.0, help="0: oracle poses")
    e.add_argument("--seed", type=int, default=1_000_000, help="first episode seed")
    e.add_argument("--num-mushrooms", type=int, default=None,
                   help="mushrooms per bed (default: the training bed size, else 25)")
    e.add_argument("--json", default=None, help="also write the result here")
    e.set_defaults(func=_cmd_eval)

    from sms3d_env import learning_curve

    learning_curve.register(subparsers)


def main(argv: list[str] | None = None) -> int:
    """``python -m sms3d_env.training {train-policy,eval-policy} ...`` (same as ``sms3d ...``)."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m sms3d_env.training")
    register(parser.add_subparsers(dest="cmd", required=True))
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    raise SystemExit(main())
