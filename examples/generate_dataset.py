"""Generate a small dataset, read it back, and draw one scene.

    python examples/generate_dataset.py --out /tmp/sms3d_ds --num-scenes 4
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless; or MUJOCO_GL=osmesa PYOPENGL_PLATFORM=osmesa

from generator import SceneConfig  # noqa: E402
from generator.dataset import DatasetOptions, RealismOptions, generate_dataset  # noqa: E402
from generator.dataset.readers import InstancePointCloudDataset, SceneDataset  # noqa: E402
from generator.dataset.show import render_overlay  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="/tmp/sms3d_ds")
    ap.add_argument("--num-scenes", type=int, default=4)
    ap.add_argument("--realism", action="store_true")
    args = ap.parse_args()
    config = SceneConfig().replace(placement__num_mushrooms=30, placement__species="mixed")
    options = DatasetOptions(realism=RealismOptions(depth_noise=args.realism, edge_holes=args.realism))
    manifest = generate_dataset(args.out, config, args.num_scenes, seed=0, options=options, workers=1)
    print({split: len(ids) for split, ids in manifest["splits"].items()})
    scenes = SceneDataset(args.out)
    first = scenes[0]
    print("scene", first["scene_id"], "rgb", tuple(first["rgb"].shape), "instances", len(first["instances"]))
    clouds = InstancePointCloudDataset(args.out, num_points=1024, cap_only=True)
    item = clouds[0]
    print("cloud", tuple(item["points"].shape), "stem axis (camera)", item["stem_axis"].numpy().round(3), item["meta"])
    print("overlay:", render_overlay(args.out, first["scene_id"], os.path.join(args.out, "overlay.png")))


if __name__ == "__main__":
    main()
