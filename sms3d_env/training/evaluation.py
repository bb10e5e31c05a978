"""``evaluate_policy_success``: a saved model (by default the shipped policy, ``SHIPPED_POLICY``)
over seeded episodes under the env id and options it was trained with: the success rate with a
95 % Wilson interval and the failure causes."""

from __future__ import annotations

import contextlib
import math
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from generator.errors import ConfigError
from sms3d_env.episode_video import EpisodeVideo
from sms3d_env.pickers.policy import PolicyActor
from sms3d_env.policies.loader import SHIPPED_POLICY
from sms3d_env.training.envs import check_bed_size, env_kwargs


def evaluate_policy_success(model_path: str | Path | None = None, episodes: int = 30,
                            pose_error_deg: float = 0.0, seed: int = 0,
                            num_mushrooms: int | None = None,
                            max_episode_steps: int | None = None, algo: str | None = None,
                            deterministic: bool = True, progress: bool = False,
                            video_dir: str | Path | None = None,
                            video_size: tuple[int, int] = (480, 640), env_id: str | None = None) -> dict[str, Any]:
    """Success of a saved policy over seeded episodes with oracle (0 deg) or noisy target poses.

    ``model_path`` None: the shipped policy. The env is the id and options the policy was trained
    with (the ``config.json`` of its run) on ``num_mushrooms``-mushroom beds (default: the
    single bed size it was trained on, else 25, the registered env's — so the shipped policy,
    trained on 10 and 25, is evaluated on 25). Episode ``i`` uses ``reset(seed=seed + i)``, so the scenes are the same for
    every model and pose error.

    ``env_id``: the env to run it in when its files do not say (a model SB3's own ``save`` wrote
    whose spaces fit several registered envs); one they name must be that
    (:class:`~sms3d_env.pickers.policy.PolicyActor`).

    ``video_dir``: also write every episode as ``episode_<seed>.mp4`` there (rendered from the
    env's ``pick`` camera at ``video_size``, (height, width) pixels, both even; annotated by
    :class:`sms3d_env.episode_video.EpisodeVideo`; needs the ``video`` extra).

    Bad arguments raise ``generator.errors.ConfigError`` naming the argument (a ``ValueError``);
    unusable model files ``PolicyFileError`` naming the file.

    Returns ``{"episodes", "successes", "success_rate", "ci95": (lo, hi), "reachable",
    "success_rate_reachable", "failure_causes": {cause: count}, "target_detached_at_end",
    "target_held_at_end" (episode counts), "mean_return", "mean_steps", "per_episode" (success
    per episode), "env_id", "env_options", "num_mushrooms", "pose_error_deg", "seed", "model",
    "videos" (the MP4s' paths, in episode order; empty without ``video_dir``)}``.
    """
    from tqdm import tqdm

    from sms3d_env.study.statistics import wilson_interval

    for name, value, least in (("episodes", episodes, 1), ("seed", seed, 0),
                               ("max_episode_steps", max_episode_steps, 1)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < least):
            raise ConfigError(name, f"must be an integer >= {least}, got {value!r}")
    if not (isinstance(pose_error_deg, (int, float)) and math.isfinite(pose_error_deg) and pose_error_deg >= 0):
        raise ConfigError("pose_error_deg", f"must be a finite number >= 0, got {pose_error_deg!r}")
    if num_mushrooms is not None:
        check_bed_size("num_mushrooms", num_mushrooms)
    if video_dir is not None:
        if not (len(video_size) == 2 and all(isinstance(n, int) and n >= 16 and n % 2 == 0 for n in video_size)):
            raise ConfigError("video_size", f"must be two even integers >= 16 (height, width; H.264 halves "
                                            f"the colour resolution), got {video_size!r}")
        video_dir = _video_folder(video_dir)
    actor = PolicyActor(SHIPPED_POLICY if model_path is None else model_path, algo, deterministic, env_id)
    trained_on = actor.saved.get("num_mushrooms")
    num_mushrooms = num_mushrooms or (trained_on if isinstance(trained_on, int) else 25)
    kw = {**env_kwargs(num_mushrooms, pose_error_deg),
          "max_episode_steps": max_episode_steps or actor.saved.get("max_episode_steps", 250)}
    from sms3d_env.training.threads import torch_threads

    with torch_threads(1):  # per-step inference of a small MLP: more threads only add overhead
        env = actor.make_env(**kw, **({"render_mode": "rgb_array", "render_camera": {"size": tuple(video_size)}}
                                      if video_dir else {}))
        causes: Counter[str] = Counter()
        successes = reachable = reach_succ = detached = held = 0
        returns, lengths, per_episode, videos = [], [], [], []
        try:
            for i in tqdm(range(episodes), desc="eval-policy", disable=not progress, unit="ep"):
                obs, info = env.reset(seed=seed + i)
                done, total, steps = False, 0.0, 0
                video = None if video_dir is None else video_dir / f"episode_{seed + i}.mp4"
                with EpisodeVideo(env, video) if video else contextlib.nullcontext() as recorder:
                    if recorder:
                        recorder.capture(info)
                    while not done:
                        obs, reward, terminated, truncated, info = env.step(actor(obs))
                        total += float(reward)
                        steps += 1
                        done = terminated or truncated
                        if recorder:
                            recorder.capture(info, ended=done)
                if video:
                    videos.append(str(video))
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
    lo, hi = wilson_interval(successes, episodes)
    return {
        "model": str(actor.path), "episodes": episodes, "successes": successes,
        "success_rate": successes / episodes, "ci95": (lo, hi), "reachable": reachable,
        "success_rate_reachable": reach_succ / reachable if reachable else math.nan,
        "failure_causes": dict(sorted(causes.items())),
        "target_detached_at_end": detached, "target_held_at_end": held, "mean_return": float(np.mean(returns)),
        "mean_steps": float(np.mean(lengths)), "per_episode": per_episode, "env_id": actor.env_id,
        "env_options": actor.env_options, "num_mushrooms": num_mushrooms,
        "pose_error_deg": float(pose_error_deg), "seed": seed, "videos": videos,
    }


def _video_folder(path: str | Path) -> Path:
    """``path`` as a folder for episode videos, made if missing; ``ConfigError`` naming ``video``
    for an empty path, a file, or a missing imageio-ffmpeg (before any episode runs)."""
    import importlib.util

    if not str(path).strip():
        raise ConfigError("video", "must name a folder, got an empty path")
    folder = Path(path)
    if folder.exists() and not folder.is_dir():
        raise ConfigError("video", f"{path} is a file; name a folder for the videos")
    if importlib.util.find_spec("imageio_ffmpeg") is None:
        raise ConfigError("video", 'videos need imageio-ffmpeg: pip install "sms3d-pick[video]"')
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def success_line(res: dict[str, Any]) -> str:
    """``success K/N (P %, 95 % CI lo-hi %); failures: cause n, ...`` of an evaluation result."""
    lo, hi = res["ci95"]
    causes = ", ".join(f"{c} {n}" for c, n in res["failure_causes"].items()) or "none"
    return (f"success {res['successes']}/{res['episodes']} ({100 * res['success_rate']:.1f} %, "
            f"95 % CI {100 * lo:.1f}-{100 * hi:.1f} %); failures: {causes}")
