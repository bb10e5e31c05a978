"""``sms3d train-detector`` / ``eval-detector`` / ``eval-pipeline`` / ``show-estimates``.

``register(subparsers)`` adds the four subcommands to ``sms3d``; each reads a dataset written by
``sms3d generate``. ``--detector`` is ``oracle`` (MuJoCo's segmentation masks) or a checkpoint
written by ``train-detector``; ``--weights`` a pose-network checkpoint (default: the shipped one).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from perception.choices import ARCHITECTURES, CATEGORIES

# torch, torchvision and the dataset readers are imported inside the commands: ``register`` runs
# for every ``sms3d`` invocation, ``--help`` included, and loading them takes seconds.

SPLITS = ("train", "val", "test")

#: ``--out`` and ``--overwrite`` of every training command (``generator.run_folder``'s rule).
RUN_FOLDER_HELP = ("run folder (last.pt, best.pt, log.csv, run_settings.json). Rerun with the same settings, the "
                   "command resumes from the last finished epoch (more --epochs extend a run, restarting the warm-up + cosine schedule over the new length); other settings are "
                   "refused, naming each")
OVERWRITE_HELP = "empty --out and start anew, instead of resuming its run or refusing other settings"
#: What ``--out`` is when the command runs a recipe (``perception.recipe``).
RECIPE_OUT_HELP = ("; with a RECIPE, default the recipe's out, and a recipe of several steps trains step NAME in "
                   "OUT/NAME; without one, required")


def run_folder_flags(p: argparse.ArgumentParser, runs_recipes: bool = False) -> None:
    """``--out`` and how a rerun treats the run in it (``generator.run_folder``'s rule), for the
    training commands that resume; a command that ``runs_recipes`` may take its ``--out`` from a
    recipe (:func:`recipe_flags`)."""
    if runs_recipes:
        p.add_argument("--out", help=RUN_FOLDER_HELP + RECIPE_OUT_HELP)
    else:
        p.add_argument("--out", required=True, help=RUN_FOLDER_HELP)
    rerun = p.add_mutually_exclusive_group()
    rerun.add_argument("--resume", action="store_true",
                       help="only continue the run in --out: refuse when it holds none (a rerun with the same "
                            "settings resumes without this flag too)")
    rerun.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)


def recipe_flags(p: argparse.ArgumentParser, shipped: str, run_flags: Sequence[str]) -> None:
    """The positional RECIPE of a training command that runs recipes (``perception.recipe``;
    ``shipped`` names the shipped network's, ``run_flags`` the command's flags that replace a
    recipe's options) and the flags that only apply with one."""
    p.add_argument("recipe", nargs="?", metavar="RECIPE",
                   help=f"a shipped recipe ({shipped}: the shipped network's, perception/recipes/{shipped}.yml) or a "
                        "recipe file: generate its datasets where missing, then train its steps in order, each "
                        "resuming when run again. The recipe sets the datasets and training options; the flags "
                        f"that apply with it are --out, --data-root, {', '.join(run_flags)} (replacing the "
                        "recipe's), --overwrite (every step starts anew; the datasets are kept) and --dry-run")
    p.add_argument("--data-root", metavar="DIR",
                   help="with a RECIPE: the folder its datasets are generated in and read from (default the recipe's "
                        "data_root)")
    p.add_argument("--dry-run", action="store_true",
                   help="with a RECIPE: print the sms3d commands it runs, one a line, and run none")


def check_without_recipe(args: argparse.Namespace, required: Sequence[str], shipped: str) -> None:
    """A training command run without a RECIPE: each flag in ``required`` is given and the
    recipe-only flags are not; ``PerceptionConfigError`` naming the flag."""
    from perception.errors import PerceptionConfigError

    for flag in ("--data-root", "--dry-run"):
        if getattr(args, flag[2:].replace("-", "_")):
            raise PerceptionConfigError(flag, f"applies only with a RECIPE (e.g. sms3d {args.command} {shipped})")
    for flag in required:
        if getattr(args, flag[2:].replace("-", "_")) is None:
            raise PerceptionConfigError(flag, f"required without a RECIPE (e.g. sms3d {args.command} {shipped}, the "
                                              "shipped network's recipe)")


def check_out(out: str, resume: bool) -> None:
    """``--out`` checked before minutes of rendering or cropping, and with ``--resume`` it must
    hold a run (a rerun resumes without the flag too; with it, a mistyped ``--out`` is refused
    rather than started afresh)."""
    from generator.run_folder import SETTINGS_FILE, check_out_path
    from perception.errors import PerceptionConfigError

    folder = check_out_path(out)
    if resume and not (folder / SETTINGS_FILE).is_file():
        raise PerceptionConfigError("--resume", f"{folder} holds no run to resume (no {SETTINGS_FILE}); drop "
                                                "--resume to start one")


def _clear_errors(func):
    """Typed input errors become one line on stderr and exit code 2, not a traceback."""

    def run(args: argparse.Namespace) -> int:
        # Imported when the command runs, not when ``register`` wraps it (perception.pipeline
        # loads torch).
        from generator.dataset.errors import DatasetError
        from generator.run_folder import RunFolderError
        from perception.errors import (
            CheckpointFormatError,
            CheckpointMismatchError,
            PerceptionConfigError,
        )
        from perception.pipeline import PipelineInputError

        try:
            return func(args)
        except (PerceptionConfigError, CheckpointFormatError, CheckpointMismatchError, DatasetError, RunFolderError,
                PipelineInputError, FileNotFoundError, ImportError) as exc:
            print(f"sms3d {args.command}: error: {exc}", file=sys.stderr)
            return 2

    return run


@contextmanager
def flag_errors(flag: str) -> Iterator[None]:
    """A file that ``flag`` names and that cannot be used (missing, unreadable, another network's)
    is reported under the flag: ``PerceptionConfigError`` naming both."""
    from perception.errors import (
        CheckpointFormatError,
        CheckpointMismatchError,
        PerceptionConfigError,
    )

    try:
        yield
    except (FileNotFoundError, CheckpointFormatError, CheckpointMismatchError) as exc:
        raise PerceptionConfigError(flag, str(exc)) from exc


def check_datasets(flag: str, roots: Sequence[str | Path]) -> None:
    """Every dataset folder ``flag`` names, checked before any is read, so that a mistyped last
    one does not cost an evaluation or training of the others: each must hold a readable
    ``manifest.json``, and none may be given twice (its scenes would count twice).
    ``PerceptionConfigError`` naming the flag and the folder."""
    from generator.dataset.errors import DatasetError
    from generator.dataset.readers import scene_indices
    from perception.errors import PerceptionConfigError

    seen: dict[Path, str | Path] = {}
    for root in roots:
        folder = Path(root).resolve()
        if folder in seen:
            raise PerceptionConfigError(flag, f"{root} is given twice (as {seen[folder]} and {root}, one folder); "
                                              "name each dataset once")
        seen[folder] = root
        try:
            scene_indices(root, None)
        except DatasetError as exc:
            raise PerceptionConfigError(flag, f"{exc}: not a dataset written by `sms3d generate`") from exc


def millimetres(text: str) -> float:
    """argparse type of mask trims in millimetres: a finite number >= 0 (0: off)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of millimetres, got {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0 (0: off), got {text}")
    return value


def _positive_int(text: str) -> int:
    """argparse type of counts and limits (threads, scenes, images): an integer >= 1, refused
    while parsing, before any model or dataset is loaded."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {value}")
    return value


def _set_threads(threads: int | None) -> None:
    """``--threads``; None (the default) keeps torch's own thread count, which the parser cannot
    ask for without importing torch."""
    import torch

    torch.set_num_threads(max(1, torch.get_num_threads()) if threads is None else threads)


def _pipeline(args: argparse.Namespace, datasets: Sequence[str]):
    """The pipeline ``--detector``/``--pose-model``/``--weights`` name, after printing the
    ``masks:`` and ``axes:`` lines. The flags, then the ``--data`` ``datasets``, are checked
    before any network is loaded."""
    from perception.detection.load import describe_detector, load_detector
    from perception.errors import PerceptionConfigError
    from perception.pipeline import PosePipeline
    from perception.pose.axis_cnn import AxisCNNEstimator

    oracle = args.detector == "oracle"
    for flag in ("--soil-margin-mm", "--edge-tolerance-mm"):
        if oracle and getattr(args, flag[2:].replace("-", "_")) > 0:
            raise PerceptionConfigError(flag, "trims a detector's masks; MuJoCo's (--detector oracle) are exact")
    check_datasets("--data", datasets)
    with flag_errors("--weights"):
        if args.pose_model == "axis-cnn":
            estimator = None
            axis_model = AxisCNNEstimator.from_checkpoint(args.weights) if args.weights else AxisCNNEstimator.from_pretrained()
        else:
            from perception.baselines.point_transformer.estimator import PoseEstimator

            estimator = PoseEstimator.from_checkpoint(args.weights) if args.weights else PoseEstimator.from_pretrained()
            axis_model = None
    overrides = {} if args.score_threshold is None else {"score_threshold": args.score_threshold}
    with flag_errors("--detector"):
        detector = load_detector(args.detector, **overrides)
    soil = None if args.soil_margin_mm <= 0 else args.soil_margin_mm / 1000.0
    edge = None if args.edge_tolerance_mm <= 0 else args.edge_tolerance_mm / 1000.0
    print(f"masks: {describe_detector(args.detector)}")
    if axis_model is not None:
        print(f"axes: axis CNN on RGB-D crops ({args.weights or 'shipped weights'})")
    else:
        sigma = estimator.config.depth_smoothing_px
        print(f"axes: point network ({args.weights or 'shipped weights'}); clouds: " + (
            f"depth smoothed in each mask, sigma {sigma:g} px (the network's setting)" if sigma > 0 else "raw depth"))
    return PosePipeline(estimator, detector, soil_margin_m=soil, edge_tolerance_m=edge, axis_model=axis_model), oracle


def cmd_train(args: argparse.Namespace) -> int:
    from generator.run_folder import check_out_path
    from perception.baselines.maskrcnn.config import DetectorConfig, DetectorTrainConfig
    from perception.baselines.maskrcnn.train import train_detector

    check_out_path(args.out)
    check_datasets("--data", [args.data])
    _set_threads(args.threads)
    config = DetectorConfig(arch=args.arch, category=args.category, min_size=args.min_size, max_size=args.max_size)
    train = DetectorTrainConfig(epochs=args.epochs, batch_size=args.batch_size, lr=args.lr, seed=args.seed,
                                max_images=args.max_images, pretrained=args.pretrained, augment=not args.no_augment)
    log = train_detector(args.data, args.out, config, train, overwrite=args.overwrite, device=args.device)
    print(json.dumps(log[-1] if log else {}, indent=2))
    return 0


def segmenter_train_config(args: argparse.Namespace):
    """The ``SegmenterTrainConfig`` that ``train-segmenter``'s flags give (an unset flag keeps the
    config's default)."""
    from perception.detection.segmenter_config import SegmenterTrainConfig

    return SegmenterTrainConfig(**{name: value for name in _TRAIN_SEGMENTER_FIELDS
                                   if (value := getattr(args, name)) is not None})


def cmd_train_segmenter(args: argparse.Namespace) -> int:
    if args.recipe is not None:
        from perception.recipe import run_recipe

        return run_recipe(args, register, segmenter_train_config)
    from generator.run_folder import check_out_path
    from perception.detection.train_segmenter import train_segmenter

    check_without_recipe(args, ("--data", "--out"), "segmenter")
    check_out_path(args.out)
    check_datasets("--data", args.data)
    _set_threads(args.threads)
    train = segmenter_train_config(args)
    log = train_segmenter(args.data, args.out, train=train, overwrite=args.overwrite)
    print(json.dumps(log[-1] if log else {}, indent=2))
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    from generator.files import write_atomic
    from perception.detection.detector_eval import evaluate_detector
    from perception.detection.load import describe_detector, load_detector
    from perception.errors import PerceptionConfigError

    _set_threads(args.threads)
    overrides = {} if args.score_threshold is None else {"score_threshold": args.score_threshold}
    with flag_errors("--checkpoint"):
        detector = load_detector(args.checkpoint, **overrides)
    if detector is None:
        raise PerceptionConfigError("--checkpoint", "'oracle' is the ground truth itself; name a detector")
    print(f"masks: {describe_detector(args.checkpoint)}")
    report = evaluate_detector(detector, args.data, args.split, getattr(detector.config, "category", "mushroom"),
                               args.min_area, detector.config.score_threshold, args.max_images, progress=True)
    print(report.markdown())
    if args.out:
        write_atomic(args.out, json.dumps(report.to_dict(), indent=2))
    return 0


def cmd_eval_pipeline(args: argparse.Namespace) -> int:
    from generator.files import write_atomic
    from perception.evaluation.eval_pipeline import PipelineReport, evaluate_pipeline

    _set_threads(args.threads)
    pipeline, oracle = _pipeline(args, args.data)
    report = PipelineReport.pooled([evaluate_pipeline(pipeline, data, args.split, oracle, args.min_area, args.max_scenes,
                                                      progress=True) for data in args.data])
    if len(args.data) > 1:
        print(f"pooled over {len(args.data)} datasets: {', '.join(args.data)}")
    print(report.markdown())
    if args.out:
        write_atomic(args.out, json.dumps({"summary": report.summary(), "rows": report.rows}, indent=2))
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    from generator.dataset.readers import read_scene_files
    from generator.dataset.writer import scene_dirname
    from perception.evaluation.eval_pipeline import run_scene
    from perception.plots.show_estimates import estimates_figure

    _set_threads(args.threads)
    pipeline, oracle = _pipeline(args, [args.data])
    sample = read_scene_files(Path(args.data) / scene_dirname(args.scene))
    estimates = run_scene(pipeline, sample, oracle)
    out = estimates_figure(sample, estimates, args.out, trim_mask=pipeline.trim_mask)
    print(f"wrote {out} ({len(estimates)} estimates)")
    return 0


def _common(p: argparse.ArgumentParser, several: bool = False) -> None:
    if several:
        p.add_argument("--data", required=True, nargs="+", help="dataset folders written by `sms3d generate`; several "
                                                                "are pooled into one report")
    else:
        p.add_argument("--data", required=True, help="dataset folder written by `sms3d generate`")
    p.add_argument("--threads", type=_positive_int, default=None, help="torch CPU threads (>= 1; default: torch's own)")


def _pipeline_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--detector", default="shipped",
                   help="stage 1: 'shipped' (the shipped RGB-D segmenter, default), 'oracle' (MuJoCo's segmentation "
                        "masks) or a train-segmenter / train-detector checkpoint")
    p.add_argument("--pose-model", choices=("axis-cnn", "points"), default="axis-cnn",
                   help="stage 2: 'axis-cnn' (the shipped axis CNN on RGB-D crops, default) or 'points' (the point "
                        "network on each mask's points)")
    p.add_argument("--weights", help="checkpoint of the --pose-model network (default: its shipped weights)")
    p.add_argument("--score-threshold", type=float, default=None,
                   help="detections below this score are dropped (default: the detector's own)")
    p.add_argument("--soil-margin-mm", type=float, default=0.0,
                   help="with a learned detector, drop mask pixels within this distance of the local soil depth (default 0: "
                        "off, as in PosePipeline; the shipped pose network was trained on the shipped segmenter's masks)")
    p.add_argument("--edge-tolerance-mm", type=millimetres, default=0.0,
                   help="with a learned detector, drop mask border pixels more than this much deeper than the mask's "
                        "interior beside them (default 0: off; 8-12 helps on clean renders, not with --realism)")


#: ``SegmenterTrainConfig`` fields that ``train-segmenter`` exposes, with their help; each flag's
#: default is the dataclass's.
_TRAIN_SEGMENTER_FIELDS = {
    "epochs": "passes over the training scenes, one random crop each",
    "batch_size": "crops per step",
    "crop": "square crop side in half-resolution pixels",
    "lr": "AdamW peak learning rate (linear warm-up, cosine decay)",
    "seed": "seed of crops, flips and initial weights",
    "time_limit_min": "stop after the epoch that passes this many minutes (resumable)",
    "val_every": "validate (mask F1 and AP on each folder's val split) every N epochs",
}


def _add_dataclass_flags(p: argparse.ArgumentParser, cls: type, helps: dict[str, str]) -> None:
    """One ``--flag`` per field in ``helps``, its type taken from dataclass ``cls``; unset, a flag
    is None and the field keeps the default its help shows (so that a flag given beside a recipe
    can be told from one left out)."""
    import dataclasses

    fields = {f.name: f for f in dataclasses.fields(cls)}
    for name, text in helps.items():
        default = fields[name].default
        kind = float if name in ("lr", "time_limit_min") else int
        p.add_argument(f"--{name.replace('_', '-')}", type=kind, help=f"{text} (default {default})")


def register(subparsers: argparse._SubParsersAction) -> None:
    from perception.baselines.maskrcnn.config import DetectorConfig, DetectorTrainConfig
    from perception.detection.segmenter_config import SegmenterTrainConfig

    p = subparsers.add_parser(
        "train-segmenter", help="train the RGB-D segmenter (stage 1) from a recipe or on generated datasets (resumable)",
        description="Train the RGB-D segmenter: from a recipe (sms3d train-segmenter segmenter: the shipped network's "
                    "datasets, generated where missing, and training settings) or on the dataset folders --data names.")
    recipe_flags(p, "segmenter", ["--threads"])
    p.add_argument("--data", nargs="+", help="dataset folders written by `sms3d generate` (train and val splits); "
                                             "required without a RECIPE")
    p.add_argument("--threads", type=_positive_int, default=None, help="torch CPU threads (>= 1; default: torch's own)")
    p.add_argument("--out", help=RUN_FOLDER_HELP + RECIPE_OUT_HELP)
    _add_dataclass_flags(p, SegmenterTrainConfig, _TRAIN_SEGMENTER_FIELDS)
    p.add_argument("--overwrite", "--restart", action="store_true", help=f"{OVERWRITE_HELP} (--restart: the same)")
    p.set_defaults(func=_clear_errors(cmd_train_segmenter))

    p = subparsers.add_parser("train-detector", help="train the Mask R-CNN baseline on a dataset's COCO files (resumable)")
    _common(p)
    p.add_argument("--out", required=True, help=RUN_FOLDER_HELP)
    net, train = DetectorConfig(), DetectorTrainConfig()  # the flags' defaults are the configs'
    p.add_argument("--arch", choices=ARCHITECTURES, default=net.arch)
    p.add_argument("--category", choices=tuple(CATEGORIES), default=net.category)
    p.add_argument("--epochs", type=int, default=train.epochs)
    p.add_argument("--batch-size", type=int, default=train.batch_size)
    p.add_argument("--lr", type=float, default=train.lr)
    p.add_argument("--seed", type=int, default=train.seed)
    p.add_argument("--min-size", type=int, default=net.min_size, help="shorter image side the network sees")
    p.add_argument("--max-size", type=int, default=net.max_size, help="longer image side the network sees")
    p.add_argument("--max-images", type=_positive_int, help="use only the first N training images (N >= 1; default: all)")
    p.add_argument("--pretrained", action="store_true", help="start from torchvision weights already in the torch hub cache")
    p.add_argument("--no-augment", action="store_true", help="no random flips")
    p.add_argument("--overwrite", "--restart", action="store_true", help=f"{OVERWRITE_HELP} (--restart: the same)")
    p.add_argument("--device", default="cpu")
    p.set_defaults(func=_clear_errors(cmd_train))

    p = subparsers.add_parser("eval-detector", help="COCO AP/AR and F1 (boxes and masks) of a detector on a split")
    _common(p)
    p.add_argument("--checkpoint", default="shipped",
                   help="'shipped' (the shipped RGB-D segmenter, default) or a train-segmenter / train-detector checkpoint")
    p.add_argument("--split", choices=SPLITS, default="test")
    p.add_argument("--min-area", type=int, default=16, help="ground-truth masks smaller than this are ignored")
    p.add_argument("--score-threshold", type=float, default=None, help="score threshold for F1 (default: the detector's own)")
    p.add_argument("--max-images", type=_positive_int, help="evaluate only the first N images (N >= 1; default: all)")
    p.add_argument("--out", help="also write the report as JSON here")
    p.set_defaults(func=_clear_errors(cmd_eval))

    p = subparsers.add_parser("eval-pipeline", help="detection recall/precision and pose errors of the two-stage pipeline")
    _common(p, several=True)
    _pipeline_args(p)
    p.add_argument("--split", choices=SPLITS, default="test")
    p.add_argument("--min-area", type=int, default=16)
    p.add_argument("--max-scenes", type=_positive_int, help="evaluate only the first N scenes of each dataset (N >= 1; "
                                                            "default: all)")
    p.add_argument("--out", help="also write summary and per-mushroom rows as JSON here")
    p.set_defaults(func=_clear_errors(cmd_eval_pipeline))

    p = subparsers.add_parser("show-estimates", help="PNG of estimated vs ground-truth cap boxes, on the image and in 3D")
    _common(p)
    _pipeline_args(p)
    p.add_argument("--scene", type=int, default=0, help="scene index")
    p.add_argument("--out", default="estimates.png")
    p.set_defaults(func=_clear_errors(cmd_show))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m perception.cli_detector")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
