"""``sms3d train-axis-cnn``: train the shipped stage-2 network, the axis CNN, on a detector's
masks of generated scenes. ``register(subparsers)`` adds it, and the point network's
``train-pose`` and ``eval-pose`` (:mod:`perception.baselines.point_transformer.cli`), to an
``argparse`` sub-parser group; each sets ``func`` to a callable taking the parsed args and
returning an exit code. Runnable standalone as ``python -m perception.cli_pose COMMAND ...``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from perception.baselines.point_transformer.cli import register as register_point_network
from perception.choices import AXIS_LOSSES
from perception.cli_detector import (
    check_datasets,
    check_out,
    check_without_recipe,
    flag_errors,
    recipe_flags,
    run_folder_flags,
)
from perception.errors import CheckpointFormatError, PerceptionConfigError

# torch and the networks are imported inside the command: ``register`` runs for every ``sms3d``
# invocation, ``--help`` included, and loading them takes seconds.


def axis_train_config(args: argparse.Namespace):
    """The ``AxisTrainConfig`` that ``train-axis-cnn``'s flags give (an unset flag keeps the
    config's default)."""
    from perception.pose.train_axis_cnn import AxisTrainConfig

    given = {name: getattr(args, name) for name in ("epochs", "batch_size", "lr", "seed", "time_limit_min", "loss")}
    return AxisTrainConfig(**{name: value for name, value in given.items() if value is not None})


def _check_axis_options(args: argparse.Namespace) -> None:
    """A recipe step's settings, checked as the command checks them before cutting crops."""
    from perception.pose.axis_cnn import AxisCNNConfig

    axis_train_config(args)
    AxisCNNConfig(**{name: value for name in ("width", "hidden") if (value := getattr(args, name)) is not None})


def cmd_train_axis_cnn(args: argparse.Namespace) -> int:
    if args.recipe is not None:
        from perception.recipe import run_recipe

        return run_recipe(args, register, _check_axis_options)
    import hashlib

    import torch

    from generator.dataset.errors import DatasetError
    from generator.run_folder import RunFolderError
    from perception.detection.load import SHIPPED_SEGMENTER, load_detector
    from perception.pose.axis_cnn import AxisCNNConfig, load_axis_cnn
    from perception.pose.train_axis_cnn import CropSet, cached_crops, train_axis_cnn
    from perception.pose.widen import check_growth

    masks = "shipped" if args.masks is None else args.masks
    # Every input is checked here, before minutes of crop cutting.
    try:
        check_without_recipe(args, ("--scenes", "--out"), "axis_cnn")
        check_out(args.out, args.resume)
        config = axis_train_config(args)
        with flag_errors("--init"):
            start = AxisCNNConfig() if args.init is None else load_axis_cnn(args.init)[0].config
        # an unset flag keeps --init's size
        net = AxisCNNConfig(width=start.width if args.width is None else args.width,
                            hidden=start.hidden if args.hidden is None else args.hidden)
        if args.init is not None:
            check_growth(start, net.width, net.hidden)
        if masks == "oracle":
            raise PerceptionConfigError("--masks", "must name a detector ('shipped' or a checkpoint), not 'oracle'")
        check_datasets("--scenes", args.scenes)
        with flag_errors("--masks"):
            detector = load_detector(masks)
    except (PerceptionConfigError, RunFolderError) as exc:
        print(f"sms3d train-axis-cnn: error: {exc}", file=sys.stderr)
        return 2
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    weights = SHIPPED_SEGMENTER if masks == "shipped" else Path(masks)
    detector_id = hashlib.sha256(weights.read_bytes()).hexdigest()[:16]
    try:
        sets = {split: CropSet.concatenate([cached_crops(root, split, detector, detector_id, args.cache, progress=True)
                                            for root in args.scenes]) for split in ("train", "val")}
    except DatasetError as exc:  # e.g. a scene file that is corrupt
        print(f"sms3d train-axis-cnn: error: {exc}", file=sys.stderr)
        return 2
    print(f"crops: {len(sets['train'])} training, {len(sets['val'])} validation")
    try:
        best = train_axis_cnn(sets["train"], sets["val"], args.out, config, net=net, overwrite=args.overwrite,
                              init=args.init, extra={"scenes": [str(Path(r).resolve()) for r in args.scenes],
                                                     "masks": masks})
    except (PerceptionConfigError, RunFolderError, CheckpointFormatError) as exc:
        print(f"sms3d train-axis-cnn: error: {exc}", file=sys.stderr)
        return 2
    print(f"best epoch {best['epoch']}: validation mean axis error {best['val_mean_axis_deg']:.2f}° "
          f"(median {best['val_median_axis_deg']:.2f}°) -> {Path(args.out) / 'best.pt'}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``train-pose``, ``eval-pose`` (the point network, a baseline) and ``train-axis-cnn``."""
    register_point_network(subparsers)
    a = subparsers.add_parser(
        "train-axis-cnn", help="train the axis CNN (stage 2 from RGB-D crops) from a recipe or on a detector's masks of "
                               "generated scenes",
        description="Train the axis CNN: from a recipe (sms3d train-axis-cnn axis_cnn: the shipped network's datasets, "
                    "generated where missing, and its eleven training steps) or on the crops of the dataset folders "
                    "--scenes names. Unset, the training flags keep AxisTrainConfig's defaults.")
    recipe_flags(a, "axis_cnn", ["--threads", "--cache"])
    run_folder_flags(a, runs_recipes=True)
    a.add_argument("--scenes", nargs="+",
                   help="dataset folders written by `sms3d generate`: their train and val splits; required without a "
                        "RECIPE")
    a.add_argument("--masks",
                   help="whose masks are cropped: 'shipped' (the shipped RGB-D segmenter, default) or a detector checkpoint")
    a.add_argument("--cache", help="folder for the crops of each dataset split (reused while the split's scenes, known "
                                   "by the checksums `sms3d generate` recorded, and the detector are the same)")
    a.add_argument("--epochs", type=int, help="passes over the training crops")
    a.add_argument("--batch-size", type=int, help="crops per step")
    a.add_argument("--lr", type=float, help="peak learning rate (warm-up, then cosine decay)")
    a.add_argument("--seed", type=int, help="seed of the initial weights, the batch order and each batch's quarter turn "
                                            "and mirror image")
    a.add_argument("--loss", choices=AXIS_LOSSES,
                   help="'angle' (the angle itself, what the mean axis error measures; default) or 'cosine' (1 - cos)")
    a.add_argument("--threads", type=int, help="torch CPU threads (default: torch's own)")
    a.add_argument("--time-limit-min", type=float, help="stop after the epoch that passes this many minutes")
    a.add_argument("--init", help="start from this axis-CNN checkpoint's weights (e.g. the shipped "
                                  "perception/weights/axis_cnn/axis_cnn.pt) instead of the upright prior")
    a.add_argument("--width", type=int, help="channels after the first conv block (default 32, or --init's); with "
                                             "--init, widen that network to this many, keeping its function (Net2Net)")
    a.add_argument("--hidden", type=int, help="hidden units of the head (default 128, or --init's); with --init, "
                                              "as --width")
    a.set_defaults(func=cmd_train_axis_cnn)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m perception.cli_pose")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    raise SystemExit(main())
