"""``sms3d train-pose`` / ``sms3d eval-pose``: argparse subcommands for the pose network.

``register(subparsers)`` adds both to an existing ``argparse`` sub-parser group; each sets
``func`` to a callable taking the parsed args and returning an exit code. Runnable standalone as
``python -m perception.cli_pose {train-pose,eval-pose} ...``.

Data: ``--scenes DIR [DIR ...]`` reads per-instance clouds from rendered scene datasets
(``generator.dataset``; splits train/val, or ``--split`` for evaluation), cut out by the
renderer's masks or, with ``--masks shipped|CHECKPOINT``, by a detector's; ``--data`` reads per-instance samples from a ``.npz`` in the :mod:`perception.pose.data`
format (``--val-data`` likewise); without it, single-mushroom views are rendered on the fly by
:mod:`perception.pose.synthetic_views` from the generator's model library with the given seeds.
``--add-synthetic N`` mixes N such views into ``--scenes`` training data; ``--init CHECKPOINT``
fine-tunes from a checkpoint's weights (same network config) instead of a fresh network.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from perception.choices import AXIS_LOSSES, BACKBONE_NAMES, HEAD_NAMES, ROTATION_LOSSES
from perception.cli_detector import (
    OVERWRITE_HELP,
    RUN_FOLDER_HELP,
    check_datasets,
    flag_errors,
    millimetres,
)
from perception.errors import CheckpointFormatError, CheckpointMismatchError, PerceptionConfigError
from perception.pose.augment import AugmentConfig
from perception.pose.config import PoseNetConfig, TrainConfig

CAMERA_MODEL_HELP = (
    "rendered single-mushroom views go through the dataset's stereo camera model (every depth effect of "
    "`sms3d generate --realism`, D405) instead of 0.5 mm white depth noise"
)

# torch, the data pipeline and the networks are imported inside the commands: ``register`` runs
# for every ``sms3d`` invocation, ``--help`` included, and loading them takes seconds.

DEFAULT_TRAIN_MODEL_IDS = (0, 1, 2, 3, 4, 5)  # model 6 of each species is held out


def _ids(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected comma-separated ints, got {text!r}") from exc


def _samples(
    data: str | None, n: int, seed: int, model_ids: Sequence[int] | None, cache: Path | None, label: str,
    procedural: int = 0, camera_model: bool = False,
):  # fmt: skip
    from perception.pose.data import load_samples, save_samples
    from perception.pose.synthetic_views import (
        ViewConfig,
        default_models,
        generate_samples,
        procedural_mesh_models,
    )

    if data:
        return load_samples(data)
    shapes = f"procedural{procedural}" if procedural else f"models{'-'.join(map(str, model_ids or []))}"
    if cache is not None:
        path = cache / f"{label}_n{n}_seed{seed}_{shapes}{'_camera' if camera_model else ''}.npz"
        if path.exists():
            return load_samples(path)
    t = time.perf_counter()
    models = procedural_mesh_models(procedural, seed) if procedural else default_models(model_ids=model_ids)
    samples = generate_samples(n, seed, models, ViewConfig(camera_model=camera_model))
    camera = ", camera model" if camera_model else ""
    print(f"rendered {n} {label} views (seed {seed}{camera}) in {time.perf_counter() - t:.1f} s", file=sys.stderr)
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        save_samples(path, samples)
    return samples


def _scene_detector(args: argparse.Namespace):
    """The detector whose masks cut ``--scenes`` into clouds (None: the renderer's), after the
    flags that depend on it are checked."""
    from perception.detection.load import load_detector

    if args.masks == "oracle":
        for flag, given in (("--edge-tolerance-mm", args.edge_tolerance_mm),
                            ("--depth-smoothing-px", args.depth_smoothing_px)):
            if given:
                raise PerceptionConfigError(flag, "cuts a detector's clouds; needs --masks shipped or a checkpoint")
        return None
    if args.cap_only:
        raise PerceptionConfigError("--cap-only", "needs --masks oracle (detectors find whole mushrooms)")
    with flag_errors("--masks"):
        return load_detector(args.masks)


def _scene_samples(args: argparse.Namespace, detector, split: str, seed: int) -> list:
    """Per-instance samples of every ``--scenes`` folder's ``split``, cut out by ``detector``'s
    masks (None: the renderer's)."""
    from perception.pose.data import samples_from_detections, samples_from_scenes

    if detector is None:
        return [s for root in args.scenes for s in samples_from_scenes(root, split, cap_only=args.cap_only, seed=seed)]
    from perception.pipeline import PosePipeline

    # The pipeline's own cut, without a network: the clouds are taken as it will take them.
    cut = PosePipeline(None, detector=None,  # type: ignore[arg-type]
                       edge_tolerance_m=args.edge_tolerance_mm / 1000.0 if args.edge_tolerance_mm > 0 else None,
                       depth_smoothing_px=args.depth_smoothing_px)
    return [s for root in args.scenes
            for s in samples_from_detections(root, split, detector, seed=seed, progress=not args.quiet,
                                             cloud_pixels=cut.cloud_pixels)]


def _check_out(args: argparse.Namespace) -> None:
    """``--out`` checked before minutes of rendering or cropping, and with ``--resume`` it must
    hold a run (a rerun resumes without the flag too; with it, a mistyped ``--out`` is refused
    rather than started afresh)."""
    from generator.run_folder import SETTINGS_FILE, check_out_path

    out = check_out_path(args.out)
    if args.resume and not (out / SETTINGS_FILE).is_file():
        raise PerceptionConfigError("--resume", f"{out} holds no run to resume (no {SETTINGS_FILE}); drop --resume "
                                                "to start one")


def cmd_train(args: argparse.Namespace) -> int:
    import torch

    from generator.run_folder import RunFolderError
    from perception.pose.data import PointCloudPoseDataset
    from perception.pose.pose_net import PoseNet, load_backbone, load_weights
    from perception.pose.train import train

    torch.set_num_threads(args.threads)
    try:
        _check_out(args)
        net = PoseNetConfig(backbone=args.backbone, head=args.head, use_rgb=args.rgb, num_points=args.num_points,
                            depth_smoothing_px=args.depth_smoothing_px)
        cfg = TrainConfig(
            epochs=args.epochs, batch_size=args.batch_size, lr=args.lr, loss=args.loss, seed=args.seed,
            device=args.device, plateau_patience=args.patience, progress=not args.quiet,
            time_limit_s=None if args.time_limit_min is None else args.time_limit_min * 60.0,
            select_by=args.select_by,
            augment=AugmentConfig(occlusion_prob=args.occlusion_prob, occlusion_fraction=tuple(args.occlusion_fraction)),
        )  # fmt: skip
    except (PerceptionConfigError, RunFolderError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    cache = Path(args.cache) if args.cache else None
    for flag, given in (("--add-synthetic", args.add_synthetic), ("--edge-tolerance-mm", args.edge_tolerance_mm),
                        ("--depth-smoothing-px", args.depth_smoothing_px)):
        if given and not args.scenes:
            print(f"error: {flag} needs --scenes", file=sys.stderr)
            return 2
    renders_views = bool(args.add_synthetic) if args.scenes else not (args.data or args.val_data)
    if args.camera_model and not renders_views:
        print("error: --camera-model applies to rendered views: with --scenes add --add-synthetic N; "
              "drop --data / --val-data (their views were rendered already)", file=sys.stderr)
        return 2
    try:  # every file named, checked before minutes of rendering or cutting
        detector = _scene_detector(args) if args.scenes else None
        if args.scenes:
            check_datasets("--scenes", args.scenes)
        for flag, path, load in (("--init", args.init, load_weights), ("--init-backbone", args.init_backbone, load_backbone)):
            if path is not None:
                with flag_errors(flag):
                    load(PoseNet(net), path)
    except PerceptionConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.scenes:
        train_s = _scene_samples(args, detector, "train", args.seed)
        val_s = _scene_samples(args, detector, "val", args.seed + 1)
        if args.add_synthetic:
            train_s = train_s + _samples(
                None, args.add_synthetic, args.seed * 1000 + 1, args.model_ids, cache, "train", args.procedural_models,
                args.camera_model,
            )
        print(f"training on {len(train_s)} instances, validating on {len(val_s)}", file=sys.stderr)
    else:
        train_s = _samples(
            args.data, args.num_train, args.seed * 1000 + 1, args.model_ids, cache, "train", args.procedural_models,
            args.camera_model,
        )
        val_s = _samples(
            args.val_data, args.num_val, args.seed * 1000 + 2, args.model_ids, cache, "val", 0, args.camera_model
        )
    tr = PointCloudPoseDataset(train_s, net.num_points, net.use_rgb, cfg.augment, seed=args.seed)
    va = PointCloudPoseDataset(val_s, net.num_points, net.use_rgb, None, seed=args.seed + 1)
    t = time.perf_counter()
    try:
        _, rows = train(net, cfg, tr, va, args.out, overwrite=args.overwrite, init=args.init,
                        init_backbone=args.init_backbone)
    except (CheckpointMismatchError, CheckpointFormatError, FileNotFoundError, RunFolderError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    best = min(rows, key=lambda r: r["val_loss"]) if rows else {}
    print(json.dumps({"train_time_s": time.perf_counter() - t, "epochs": len(rows), "best": best}, indent=2))
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    import torch

    from perception.pose.data import PointCloudPoseDataset, samples_from_scenes
    from perception.pose.estimator import default_weights_path
    from perception.pose.pose_net import load_checkpoint
    from perception.pose.train import evaluate

    if args.camera_model and (args.scenes or args.data):
        print("error: --camera-model applies to rendered views: drop --scenes / --data", file=sys.stderr)
        return 2
    torch.set_num_threads(args.threads)

    path = Path(args.checkpoint) if args.checkpoint else default_weights_path()
    try:
        with flag_errors("--checkpoint"):
            model, extra = load_checkpoint(path, map_location=args.device)
        if args.scenes:
            check_datasets("--scenes", [args.scenes])
    except PerceptionConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    net = model.config
    if args.scenes:
        samples = samples_from_scenes(args.scenes, args.split, cap_only=args.cap_only, seed=args.seed)
    else:
        samples = _samples(args.data, args.num, args.seed, args.model_ids, None, "test", 0, args.camera_model)
    ds = PointCloudPoseDataset(samples, net.num_points, net.use_rgb, None, seed=args.seed)
    _, m, *_ = evaluate(model, ds, device=args.device)
    print(json.dumps({"checkpoint": str(path), "config": net.to_dict(), **m.as_dict()}, indent=2))
    return 0


def cmd_train_axis_cnn(args: argparse.Namespace) -> int:
    import hashlib

    import torch

    from generator.dataset.errors import DatasetError
    from generator.run_folder import RunFolderError
    from perception.detection.load import SHIPPED_SEGMENTER, load_detector
    from perception.pose.axis_cnn import AxisCNNConfig, load_axis_cnn
    from perception.pose.train_axis_cnn import (
        AxisTrainConfig,
        CropSet,
        cached_crops,
        train_axis_cnn,
    )
    from perception.pose.widen import check_growth

    # Every input is checked here, before minutes of crop cutting.
    try:
        _check_out(args)
        config = AxisTrainConfig(epochs=args.epochs, batch_size=args.batch_size, lr=args.lr, seed=args.seed,
                                 time_limit_min=args.time_limit_min, loss=args.loss)
        with flag_errors("--init"):
            start = AxisCNNConfig() if args.init is None else load_axis_cnn(args.init)[0].config
        # an unset flag keeps --init's size
        net = AxisCNNConfig(width=start.width if args.width is None else args.width,
                            hidden=start.hidden if args.hidden is None else args.hidden)
        if args.init is not None:
            check_growth(start, net.width, net.hidden)
        if args.masks == "oracle":
            raise PerceptionConfigError("--masks", "must name a detector ('shipped' or a checkpoint), not 'oracle'")
        check_datasets("--scenes", args.scenes)
        with flag_errors("--masks"):
            detector = load_detector(args.masks)
    except (PerceptionConfigError, RunFolderError) as exc:
        print(f"sms3d train-axis-cnn: error: {exc}", file=sys.stderr)
        return 2
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    weights = SHIPPED_SEGMENTER if args.masks == "shipped" else Path(args.masks)
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
                                                     "masks": args.masks})
    except (PerceptionConfigError, RunFolderError, CheckpointFormatError) as exc:
        print(f"sms3d train-axis-cnn: error: {exc}", file=sys.stderr)
        return 2
    print(f"best epoch {best['epoch']}: validation mean axis error {best['val_mean_axis_deg']:.2f}° "
          f"(median {best['val_median_axis_deg']:.2f}°) -> {Path(args.out) / 'best.pt'}")
    return 0


def _run_folder_flags(p: argparse.ArgumentParser) -> None:
    """``--out`` and how a rerun treats the run in it (``generator.run_folder``'s rule)."""
    p.add_argument("--out", required=True, help=RUN_FOLDER_HELP)
    rerun = p.add_mutually_exclusive_group()
    rerun.add_argument("--resume", action="store_true",
                       help="only continue the run in --out: refuse when it holds none (a rerun with the same "
                            "settings resumes without this flag too)")
    rerun.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``train-pose``, ``eval-pose`` and ``train-axis-cnn`` to ``subparsers``."""
    p = subparsers.add_parser("train-pose", help="train the pose network on rendered single-mushroom views")
    _run_folder_flags(p)
    net, train = PoseNetConfig(), TrainConfig()  # the flags' defaults are the configs'
    p.add_argument("--backbone", default=net.backbone, choices=BACKBONE_NAMES)
    p.add_argument("--head", default=net.head, choices=HEAD_NAMES)
    p.add_argument("--rgb", action="store_true", help="feed RGB with the points")
    p.add_argument("--num-points", type=int, default=net.num_points)
    p.add_argument("--epochs", type=int, default=train.epochs)
    p.add_argument("--batch-size", type=int, default=train.batch_size)
    p.add_argument("--lr", type=float, default=train.lr)
    p.add_argument("--patience", type=int, default=train.plateau_patience, help="ReduceLROnPlateau patience (epochs)")
    p.add_argument("--loss", default=train.loss, choices=ROTATION_LOSSES)
    p.add_argument("--num-train", type=int, default=4000)
    p.add_argument("--num-val", type=int, default=500)
    p.add_argument("--model-ids", type=_ids, default=DEFAULT_TRAIN_MODEL_IDS, help="generator model ids to render")
    p.add_argument(
        "--procedural-models", type=int, default=0, metavar="N",
        help="render training views of N fresh procedural shapes per species (seeded by --seed) instead of "
             "the library's --model-ids; validation views stay on --model-ids",
    )  # fmt: skip
    p.add_argument("--data", help="training samples .npz (perception.pose.data format) instead of rendering")
    p.add_argument("--val-data", help="validation samples .npz")
    p.add_argument("--scenes", nargs="+", help="rendered scene dataset folders (generator.dataset): their train/val splits")
    p.add_argument("--masks", default="oracle",
                   help="with --scenes: whose masks cut out each mushroom's points: 'oracle' (the renderer's, default), "
                        "'shipped' (the shipped RGB-D segmenter's, matched to the truth by IoU >= 0.5) or a detector "
                        "checkpoint")
    p.add_argument("--edge-tolerance-mm", type=millimetres, default=0.0,
                   help="with a detector's --masks: cut each mask as `eval-pipeline --edge-tolerance-mm` does "
                        "(border pixels this much deeper than the interior dropped; default 0: whole masks)")
    p.add_argument("--depth-smoothing-px", type=float, default=net.depth_smoothing_px, metavar="SIGMA",
                   help="with a detector's --masks: smooth each mask's depth with a Gaussian of SIGMA pixels before "
                        "taking its points; saved with the network, so the pipeline feeds it the same way "
                        "(default 0: raw depth)")
    p.add_argument("--cap-only", action="store_true", help="with --scenes and oracle masks: cap points only")
    p.add_argument("--cache", help="folder to cache rendered views as .npz")
    p.add_argument("--time-limit-min", type=float, help="stop after the epoch that passes this wall time")
    p.add_argument("--select-by", choices=("loss", "axis"), default=train.select_by,
                   help="which epoch best.pt keeps: lowest validation loss or lowest mean stem-axis error")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="cpu")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--init", help="start from this checkpoint's weights (fine-tune; same network shape)")
    p.add_argument(
        "--init-backbone", metavar="CHECKPOINT",
        help="start from this checkpoint's backbone and hidden head layer; a fresh output layer (e.g. another --head)",
    )  # fmt: skip
    p.add_argument(
        "--add-synthetic", type=int, default=0, metavar="N",
        help="with --scenes: also train on N rendered single-mushroom views (seed SEED*1000+1, --model-ids)",
    )  # fmt: skip
    p.add_argument("--camera-model", action="store_true", help=CAMERA_MODEL_HELP)
    augment = AugmentConfig()
    p.add_argument("--occlusion-prob", type=float, default=augment.occlusion_prob, metavar="P",
                   help="hide a bite of each training cloud with probability P, as a neighbour in front would "
                        "(default %(default)s: off)")
    p.add_argument("--occlusion-fraction", type=float, nargs=2, default=augment.occlusion_fraction,
                   metavar=("MIN", "MAX"), help="the share of a cloud's points the bite hides (default: 0.2 0.6)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_train)

    e = subparsers.add_parser("eval-pose", help="evaluate a pose checkpoint (default: shipped weights)")
    e.add_argument("--checkpoint", help="checkpoint path (default: perception/weights/posenet_default.pt)")
    e.add_argument("--data", help="samples .npz; default: render --num views with --seed")
    e.add_argument("--scenes", help="rendered scene dataset folder (generator.dataset)")
    e.add_argument("--split", default="test", help="with --scenes: which split")
    e.add_argument("--cap-only", action="store_true", help="with --scenes: cap points only")
    e.add_argument("--num", type=int, default=500)
    e.add_argument("--seed", type=int, default=12345)
    e.add_argument("--model-ids", type=_ids, default=None, help="generator model ids (default: all)")
    e.add_argument("--camera-model", action="store_true", help=CAMERA_MODEL_HELP)
    e.add_argument("--device", default="cpu")
    e.add_argument("--threads", type=int, default=2)
    e.set_defaults(func=cmd_eval)

    a = subparsers.add_parser(
        "train-axis-cnn", help="train the axis CNN (stage 2 from RGB-D crops) on a detector's masks of generated scenes")
    _run_folder_flags(a)
    a.add_argument("--scenes", nargs="+", required=True,
                   help="dataset folders written by `sms3d generate`: their train and val splits")
    a.add_argument("--masks", default="shipped",
                   help="whose masks are cropped: 'shipped' (the shipped RGB-D segmenter, default) or a detector checkpoint")
    a.add_argument("--cache", help="folder for the crops of each dataset split (reused while the split's scenes, known "
                                   "by the checksums `sms3d generate` recorded, and the detector are the same)")
    a.add_argument("--epochs", type=int, default=60)
    a.add_argument("--batch-size", type=int, default=128)
    a.add_argument("--lr", type=float, default=2e-3, help="peak learning rate (warm-up, then cosine decay)")
    a.add_argument("--seed", type=int, default=0)
    a.add_argument("--loss", choices=AXIS_LOSSES, default="angle",
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
