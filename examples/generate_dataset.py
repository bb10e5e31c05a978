"""Generate a small dataset, read it back, and draw one scene (its masks and cap boxes, titled).

    python examples/generate_dataset.py --out out/examples/dataset --num-scenes 4
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless; or MUJOCO_GL=osmesa PYOPENGL_PLATFORM=osmesa


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/examples/dataset",
                    help="dataset folder (default out/examples/dataset; the repository ignores out/)")
    ap.add_argument("--num-scenes", type=int, default=4)
    ap.add_argument("--realism", action="store_true", help="apply the camera model (depth noise, edge holes)")
    args = ap.parse_args()
    # Imported after parsing, so that --help answers without loading torch and MuJoCo.
    from generator import SceneConfig
    from generator.dataset import DatasetOptions, RealismOptions, generate_dataset
    from generator.dataset.readers import InstancePointCloudDataset, SceneDataset
    from generator.dataset.show import render_overlay

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
