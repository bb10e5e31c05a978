"""Run the scripted pose-aware picker once and save an image strip (side camera) as a PNG.

Usage: python examples/scripted_picker.py [--seed 0] [--pose-error-deg 0] [--out picker_strip.png]
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402
import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import sms3d_env  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pose-error-deg", type=float, default=0.0)
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--out", default="picker_strip.png")
    args = ap.parse_args()
    env = gym.make("SMS3DPick-v0", pose_source="noisy", pose_error_deg=args.pose_error_deg,
                   render_mode="rgb_array", camera="side", render_size=(240, 320))
    policy = sms3d_env.ScriptedPicker.for_env(env)
    obs, info = env.reset(seed=args.seed)
    frames = [env.render()]
    done = False
    while not done:
        obs, _, term, trunc, info = env.step(policy(obs))
        done = term or trunc
        frames.append(env.render())
    idx = np.linspace(0, len(frames) - 1, args.frames).round().astype(int)
    strip = np.concatenate([frames[i] for i in idx], axis=1)
    cv2.imwrite(args.out, cv2.cvtColor(strip, cv2.COLOR_RGB2BGR))
    print(f"success={info['is_success']} cause={info['failure_cause']} steps={len(frames) - 1} -> {args.out}")
    env.close()


if __name__ == "__main__":
    main()
