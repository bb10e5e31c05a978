"""Run the scripted pose-aware picker once and save an image strip (side camera) as a PNG.

Usage: python examples/scripted_picker.py [--seed 0] [--pose-error-deg 0] [--tool suction|hand]
       [--out picker_strip.png]
"""

from __future__ import annotations

import argparse

import gymnasium as gym

import sms3d_env
from generator.files import save_rgb_png
from sms3d_env.demo import picker_strip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pose-error-deg", type=float, default=0.0)
    ap.add_argument("--tool", choices=sms3d_env.TOOLS, default="suction")
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--out", default="picker_strip.png")
    args = ap.parse_args()
    env = gym.make("SMS3DPick-v0", pose_source="noisy", pose_error_deg=args.pose_error_deg,
                   tool=args.tool, render_mode="rgb_array", camera="side", render_size=(240, 320))
    strip, info = picker_strip(env, sms3d_env.ScriptedPicker.for_env(env), args.seed, args.frames)
    save_rgb_png(args.out, strip)
    print(f"success={info['is_success']} cause={info['failure_cause']} -> {args.out}")
    env.close()


if __name__ == "__main__":
    main()
