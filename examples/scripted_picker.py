"""Run the scripted pose-aware picker once and save frames of the pick (the env's pick camera:
time and phase on each frame, the target ringed, the outcome on the last) as a PNG, and with
``--video`` the whole pick as MP4 (needs the ``video`` extra).

Usage: python examples/scripted_picker.py [--seed 0] [--pose-error-deg 0] [--robot gantry|jaco]
       [--tool suction|hand] [--out out/examples/picker_strip.png] [--video out/examples/pick.mp4]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym

import sms3d_env
from generator.files import save_rgb_png
from sms3d_env.demo import picker_strip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pose-error-deg", type=float, default=0.0)
    ap.add_argument("--robot", choices=sms3d_env.ROBOTS, default="gantry")
    ap.add_argument("--tool", choices=sms3d_env.TOOLS, default="suction")
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--out", default="out/examples/picker_strip.png",
                    help="the strip of frames (default out/examples/picker_strip.png; the repository ignores out/)")
    ap.add_argument("--video", default=None, help="also write the pick as this MP4")
    args = ap.parse_args()
    env = gym.make("SMS3DPick-v2", pose_source="noisy", pose_error_deg=args.pose_error_deg, robot=args.robot,
                   tool=args.tool, render_mode="rgb_array", render_camera={"size": (240, 320)})
    picker = sms3d_env.ScriptedPicker.for_env(env)  # the hand's picker with the hand
    title = (f"Scripted picker, SMS3DPick-v2 {args.robot} with the {args.tool} tool, "
             f"{args.pose_error_deg:g} deg pose error, seed {args.seed}")
    for path in (args.out, args.video):
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
    strip, info = picker_strip(env, picker, args.seed, args.frames, title, args.video)
    save_rgb_png(args.out, strip)
    written = args.out + (f" and {args.video}" if args.video else "")
    print(f"success={info['is_success']} cause={info['failure_cause']} -> {written}")
    env.close()


if __name__ == "__main__":
    main()
