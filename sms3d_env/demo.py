"""``sms3d demo``: the whole project in one minute on embedded defaults.

Generates a seeded bed and renders it, then lets the scripted pose-aware picker pick with exact
poses and with a 30-degree orientation error, saving an image strip of each pick.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


def picker_strip(env: Any, policy: Any, seed: int, frames: int = 6) -> tuple[np.ndarray, dict[str, Any]]:
    """Run one episode with ``render_mode="rgb_array"`` and return ``frames`` evenly spaced renders
    side by side, and the final ``info``."""
    obs, info = env.reset(seed=seed)
    if hasattr(policy, "reset"):
        policy.reset()
    images = [env.render()]
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        done = terminated or truncated
        images.append(env.render())
    idx = np.linspace(0, len(images) - 1, frames).round().astype(int)
    return np.concatenate([images[i] for i in idx], axis=1), info


def run_demo(out: str | Path = "sms3d_demo", seed: int = 0, episodes: int = 5) -> dict[str, float]:
    """Write ``scene.png`` and picker strips into ``out``; return success rates per pose error."""
    import gymnasium as gym
    from tqdm.auto import tqdm

    import sms3d_env  # noqa: F401 - registers the environments
    from generator import SceneConfig, generate_scene
    from generator.files import save_rgb_png
    from generator.preview import save_preview
    from sms3d_env.scripted_picker import ScriptedPicker, run_episode

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    config = SceneConfig().replace(placement__num_mushrooms=25)
    save_preview(generate_scene(config, seed), out / "scene.png")
    print(f"bed of 25 mushrooms rendered: {out / 'scene.png'}")
    rates = {}
    for error in (0.0, 30.0):
        env = gym.make("SMS3DPick-v0", scene_config=config, pose_source="noisy", pose_error_deg=error,
                       render_mode="rgb_array", camera="side", render_size=(240, 320))
        picker = ScriptedPicker.for_env(env)
        strip, info = picker_strip(env, picker, seed)
        save_rgb_png(out / f"pick_error_{error:g}deg.png", strip)
        results = [run_episode(env, picker, seed + k) for k in tqdm(range(episodes), desc=f"picking, pose error {error:g}°")]
        env.close()
        reachable = [r for r in results if r["reachable"]]
        rates[error] = float(np.mean([r["success"] for r in reachable])) if reachable else float("nan")
        causes = sorted({r["failure_cause"] for r in reachable if not r["success"]})
        print(f"pose error {error:4.0f}°: {sum(r['success'] for r in reachable)}/{len(reachable)} reachable targets picked"
              f"{'; failures: ' + ', '.join(causes) if causes else ''}; strip: {out / f'pick_error_{error:g}deg.png'}")
    return rates


def register(subparsers: Any) -> None:
    """Add ``sms3d demo``."""
    p = subparsers.add_parser("demo", help="generate and render a bed, then pick with exact and 30°-wrong poses")
    p.add_argument("--out", default="sms3d_demo", help="folder for the pictures (default sms3d_demo)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--episodes", type=int, default=5, help="episodes per pose error")
    p.set_defaults(func=lambda args: (run_demo(args.out, args.seed, args.episodes), 0)[1])
