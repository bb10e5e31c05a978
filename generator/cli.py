"""``sms3d preview`` and ``sms3d scene``: one generated scene as a picture or as MJCF.

The ``sms3d`` command itself is ``sms3d_env.cli`` (the top package, the one allowed to import
the others); this module only registers the generator's own commands.
"""

from __future__ import annotations

import argparse

from generator.cli_types import image_side, output_path
from generator.config import MAX_IMAGE_SIDE, MIN_IMAGE_SIDE


def _scene_config(args: argparse.Namespace):
    from generator.config import SceneConfig

    config = SceneConfig.from_file(args.config) if getattr(args, "config", None) else SceneConfig()
    overrides = {}
    if getattr(args, "num_mushrooms", None) is not None:
        overrides["placement__num_mushrooms"] = args.num_mushrooms
    if getattr(args, "species", None) is not None:
        overrides["placement__species"] = args.species
    return config.replace(**overrides) if overrides else config


def add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    """The flags every scene-making command shares."""
    parser.add_argument("--config", help="YAML/JSON scene configuration (sections terrain, placement, camera)")
    parser.add_argument("--num-mushrooms", type=int, help="mushrooms to place (1-100)")
    parser.add_argument("--species", choices=("white", "brown", "mixed"), help="species mix")
    parser.add_argument("--seed", type=int, default=0, help="scene seed (default 0)")


def _cmd_preview(args: argparse.Namespace) -> int:
    from generator.generate import generate_scene_with_stats
    from generator.preview import save_preview

    scene, stats = generate_scene_with_stats(_scene_config(args), args.seed)
    save_preview(scene, args.out, args.width, args.height)
    print(f"placed {stats.placed}/{stats.requested} mushrooms ({stats.attempts} attempts); wrote {args.out}")
    return 0


def _cmd_scene(args: argparse.Namespace) -> int:
    from pathlib import Path

    from generator.generate import generate_scene_with_stats
    from generator.mjcf import write_mjcf

    scene, stats = generate_scene_with_stats(_scene_config(args), args.seed)
    xml = write_mjcf(scene, args.out)
    scene.save(Path(args.out) / "scene.json")
    print(f"placed {stats.placed}/{stats.requested} mushrooms; wrote {xml} and scene.json "
          f"(view with: python -m mujoco.viewer --mjcf={xml})")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sms3d preview`` and ``sms3d scene``."""
    preview = sub.add_parser("preview", help="render one generated scene to a PNG (overhead + oblique view)")
    add_scene_arguments(preview)
    preview.add_argument("--out", type=output_path, default="scene.png", help="PNG to write (default scene.png)")
    sides = f"{MIN_IMAGE_SIDE}-{MAX_IMAGE_SIDE}"
    preview.add_argument("--width", type=image_side, default=640, help=f"width of each view ({sides}, default 640)")
    preview.add_argument("--height", type=image_side, default=480, help=f"height ({sides}, default 480)")
    preview.set_defaults(func=_cmd_preview)

    scene = sub.add_parser("scene", help="write one generated scene as MJCF (scene.xml + assets) and scene.json")
    add_scene_arguments(scene)
    scene.add_argument("--out", type=output_path, required=True, help="output folder")
    scene.set_defaults(func=_cmd_scene)
