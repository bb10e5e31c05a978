"""Trace a picker through seeded episodes: every N control steps, where the cup is relative to the
*true* target (along / across the true stem axis, mm), the angle between the cup and the true
axis, the tool command and whether the cup is sealed. Used to diagnose learned pickers (a clone
that hovers at the stand-off point, a descent that drifts off the axis).

    python benchmarks/trace_picker.py --picker policy:runs/bc/model.zip --pose-error-deg 30 --episodes 3
"""

from __future__ import annotations

import argparse

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--picker", default="scripted", help="scripted or policy[:PATH]")
    p.add_argument("--pose-error-deg", type=float, default=0.0, help="0: oracle poses")
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--seed", type=int, default=0, help="first episode seed")
    p.add_argument("--every", type=int, default=10, help="print every N control steps")
    args = p.parse_args()

    from sms3d_env.pickers.registry import make_picker_env, parse_picker
    from sms3d_env.pickers.scripted import ScriptedPicker

    kw = {"pose_source": "noisy", "pose_error_deg": args.pose_error_deg} if args.pose_error_deg > 0 else {}
    env, picker = make_picker_env(parse_picker(args.picker), **kw)
    try:
        for seed in range(args.seed, args.seed + args.episodes):
            obs, info = env.reset(seed=seed)
            if hasattr(picker, "reset"):
                picker.reset()
            inst = env.unwrapped.scene.instances[info["target"]]
            cap, axis = np.asarray(inst.cap_top), np.asarray(inst.rotation)[:, 2]
            done, t, lines = False, 0, []
            while not done:
                action = picker(obs)
                if t % args.every == 0:
                    view = ScriptedPicker.view(obs)
                    rel = view.p - cap
                    along = rel @ axis
                    lines.append(f"  t={t:3d} along={1000 * along:6.1f} mm  across={1000 * np.linalg.norm(rel - along * axis):5.1f} mm  "
                                 f"angle={np.degrees(np.arccos(np.clip(view.z @ -axis, -1, 1))):5.1f}°  "
                                 f"command={action[6]:+.2f}  sealed={int(view.held)}")
                obs, _, terminated, truncated, info = env.step(action)
                done, t = terminated or truncated, t + 1
            print(f"seed {seed}: {'success' if info['is_success'] else info['failure_cause']} after {t} steps")
            print("\n".join(lines))
    finally:
        env.close()


if __name__ == "__main__":
    main()
