"""``sms3d generate`` and ``sms3d show``: ``register(subparsers)`` adds them to a CLI.

Run standalone as ``python -m generator.dataset.cli generate --out DIR ...``.
"""

from __future__ import annotations

import argparse
import sys

from generator.cli_types import output_path
from generator.errors import ConfigError


def _ratios(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError("expected three comma-separated numbers, e.g. 0.8,0.1,0.1")
    try:
        return tuple(float(p) for p in parts)  # type: ignore[return-value]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def register(subparsers: argparse._SubParsersAction) -> None:
    gen = subparsers.add_parser("generate", help="render a dataset of synthetic mushroom beds")
    gen.add_argument("--out", type=output_path, required=True, help="output folder (re-running resumes)")
    gen.add_argument("--num-scenes", type=int, required=True, help="scenes in the dataset (1-1000000)")
    gen.add_argument("--species", choices=["white", "brown", "mixed"], default=None)
    gen.add_argument("--num-mushrooms", type=int, default=None, help="mushrooms requested per scene (1-100)")
    gen.add_argument("--workers", type=int, default=1)
    gen.add_argument("--seed", type=int, default=0)
    gen.add_argument("--config", default=None, help="YAML/JSON SceneConfig file")
    gen.add_argument("--backend", choices=["process", "ray"], default="process")
    gen.add_argument("--width", type=int, default=None)
    gen.add_argument("--height", type=int, default=None)
    gen.add_argument("--split-ratios", type=_ratios, default=(0.8, 0.1, 0.1), help="train,val,test")
    gen.add_argument("--shadows", action="store_true")
    gen.add_argument("--depth-noise", action="store_true", help="RealSense-like stereo depth noise")
    gen.add_argument("--edge-holes", action="store_true", help="depth holes at depth edges")
    gen.add_argument("--lighting", action="store_true", help="randomise lighting")
    gen.add_argument("--soil", action="store_true", help="randomise soil tint and texture scale")
    gen.add_argument("--camera-jitter", action="store_true", help="jitter camera height and tilt")
    gen.add_argument("--correlated-noise", action="store_true",
                     help="stereo noise in disparity, correlated over the matching window (replaces --depth-noise)")
    gen.add_argument("--disparity-quantisation", action="store_true", help="depth on a 1/32 px disparity grid")
    gen.add_argument("--flying-pixels", action="store_true", help="mixed near/far depths at depth edges")
    gen.add_argument("--stereo-shadows", action="store_true",
                     help="invalid depth where the right imager cannot see (left of near objects, left image edge)")
    gen.add_argument("--rgb-noise", action="store_true", help="Poisson-Gaussian RGB sensor noise")
    gen.add_argument("--rgb-blur", action="store_true", help="random Gaussian blur of the RGB image")
    gen.add_argument("--exposure", action="store_true", help="random exposure gain of the RGB image")
    gen.add_argument("--realism", action="store_true", help="all realism options")
    gen.add_argument("--no-progress", action="store_true")
    gen.set_defaults(func=run_generate)

    show = subparsers.add_parser("show", help="draw one scene's masks and cap boxes on its RGB image")
    show.add_argument("dir", help="dataset folder")
    show.add_argument("--scene", type=int, required=True, help="scene index")
    show.add_argument("--out", type=output_path, required=True, help="PNG to write")
    show.add_argument("--labels", choices=["mushroom", "cap", "amodal"], default="mushroom")
    show.set_defaults(func=run_show)


def _config(args: argparse.Namespace):
    from generator.config import SceneConfig

    cfg = SceneConfig.from_file(args.config) if args.config else SceneConfig()
    overrides = {}
    if args.species is not None:
        overrides["placement__species"] = args.species
    if args.num_mushrooms is not None:
        overrides["placement__num_mushrooms"] = args.num_mushrooms
    if args.width is not None:
        overrides["camera__width"] = args.width
    if args.height is not None:
        overrides["camera__height"] = args.height
    return cfg.replace(**overrides) if overrides else cfg


def run_generate(args: argparse.Namespace) -> int:
    from generator.dataset.errors import DatasetError
    from generator.dataset.options import REALISM_SWITCHES, DatasetOptions, RealismOptions
    from generator.dataset.runner import generate_dataset

    try:
        cfg = _config(args)
        realism = RealismOptions(**{name: args.realism or getattr(args, name) for name in REALISM_SWITCHES})
        options = DatasetOptions(split_ratios=args.split_ratios, shadows=args.shadows, realism=realism)
        if args.workers < 1:
            raise ConfigError("--workers", "must be >= 1")
        manifest = generate_dataset(args.out, cfg, args.num_scenes, args.seed, options=options, workers=args.workers,
                                    backend=args.backend, progress=not args.no_progress)
    except (ConfigError, DatasetError, ValueError) as exc:
        print(f"sms3d generate: error: {exc}", file=sys.stderr)
        return 2
    counts = {s: len(v) for s, v in manifest["splits"].items()}
    print(f"{len(manifest['scenes'])} scenes in {args.out} ({counts})")
    return 0


def run_show(args: argparse.Namespace) -> int:
    from generator.dataset.errors import DatasetError
    from generator.dataset.show import render_overlay

    try:
        render_overlay(args.dir, args.scene, args.out, labels=args.labels)
    except (DatasetError, OSError, ValueError) as exc:
        print(f"sms3d show: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="sms3d")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
