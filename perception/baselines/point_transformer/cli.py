"""``sms3d train-pose`` / ``sms3d eval-pose``: train and evaluate the point network (the paper's
Point Transformer, a baseline). ``perception.cli_pose.register`` adds both to ``sms3d``.

``train-pose`` takes how the network learns from a recipe (:mod:`.recipe`: ``--recipe FILE``,
default the shipped network's ``recipe.yml``, and ``--set KEY=VALUE``), and from its flags what
the run is: where it writes (``--out``), which data (``--scenes`` clouds cut by ``--masks``, or
``--data`` / ``--val-data`` sample files, else single-mushroom views rendered on the fly by
:mod:`.synthetic_views`), where it starts (``--init``, ``--init-backbone``) and how long it runs.
The flags that set recipe entries before the recipe was a file still work, hidden, with a
warning naming the ``--set`` that replaces them (:data:`DEPRECATED_FLAGS`).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from perception.choices import BACKBONE_NAMES, HEAD_NAMES, ROTATION_LOSSES
from perception.cli_detector import (
    check_datasets,
    check_out,
    flag_errors,
    millimetres,
    run_folder_flags,
)
from perception.deprecation import deprecation_message
from perception.errors import CheckpointFormatError, CheckpointMismatchError, PerceptionConfigError

# torch, the data pipeline and the networks are imported inside the commands: ``register`` runs
# for every ``sms3d`` invocation, ``--help`` included, and loading them takes seconds.

CAMERA_MODEL_HELP = (
    "rendered single-mushroom views go through the dataset's stereo camera model (every depth effect of "
    "`sms3d generate --realism`, D405) instead of 0.5 mm white depth noise"
)


def _ids(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected comma-separated ints, got {text!r}") from exc


#: ``train-pose`` flags replaced by recipe entries, deprecated 2026-12-06 (removed after
#: 2027-06-06): flag -> (recipe key, argparse keywords). They still set the entry, with a warning.
DEPRECATED_FLAGS: dict[str, tuple[str, dict[str, Any]]] = {
    "--backbone": ("net.backbone", {"choices": BACKBONE_NAMES}),
    "--head": ("net.head", {"choices": HEAD_NAMES}),
    "--rgb": ("net.use_rgb", {"action": "store_const", "const": True}),
    "--num-points": ("net.num_points", {"type": int}),
    "--batch-size": ("train.batch_size", {"type": int}),
    "--lr": ("train.lr", {"type": float}),
    "--patience": ("train.plateau_patience", {"type": int}),
    "--loss": ("train.loss", {"choices": ROTATION_LOSSES}),
    "--select-by": ("train.select_by", {"choices": ("loss", "axis")}),
    "--occlusion-prob": ("train.augment.occlusion_prob", {"type": float}),
    "--occlusion-fraction": ("train.augment.occlusion_fraction", {"type": float, "nargs": 2}),
    "--num-train": ("data.num_train", {"type": int}),
    "--num-val": ("data.num_val", {"type": int}),
    "--model-ids": ("data.model_ids", {"type": _ids}),
    "--procedural-models": ("data.procedural_models", {"type": int}),
    "--add-synthetic": ("data.add_synthetic", {"type": int}),
    "--camera-model": ("data.camera_model", {"action": "store_const", "const": True}),
    "--cap-only": ("data.cap_only", {"action": "store_const", "const": True}),
    # Measured worse, so not in the recipe: a network trained on depth smoothed in each mask read
    # 12.3° against 8.8° mean stem-axis error on clean held-out beds (benchmarks/RESULTS.md).
    "--depth-smoothing-px": ("net.depth_smoothing_px", {"type": float}),
}
#: Deprecated with no replacement: training on clouds whose mask borders were trimmed by depth
#: measured worse with the camera model, 16.0° against 15.7° mean stem-axis error
#: (benchmarks/RESULTS.md). It still cuts the clouds until it is removed.
EDGE_TOLERANCE_FLAG = "--edge-tolerance-mm"


def _dest(flag: str) -> str:
    return "deprecated_" + flag.lstrip("-").replace("-", "_")


def _as_set_value(value: Any) -> str:
    """``value`` as ``--set`` would take it."""
    return value if isinstance(value, str) else json.dumps(list(value) if isinstance(value, tuple) else value)


def _recipe(args: argparse.Namespace):
    """The run's recipe: ``--recipe``, then the deprecated flags, then ``--set``, in that order;
    each deprecated flag given is warned about on stderr."""
    from perception.baselines.point_transformer.recipe import (
        SHIPPED_RECIPE,
        Override,
        parse_set,
        read_recipe,
    )

    overrides = []
    for flag, (key, _) in DEPRECATED_FLAGS.items():
        value = getattr(args, _dest(flag))
        if value is not None:
            instead = f"use --set {key}={_as_set_value(value)}"
            print(f"sms3d train-pose: warning: {deprecation_message(flag, instead)}", file=sys.stderr)
            overrides.append(Override(flag, key, value))
    if getattr(args, _dest(EDGE_TOLERANCE_FLAG)) is not None:
        instead = "training on depth-trimmed clouds measured worse with the camera model (benchmarks/RESULTS.md)"
        print(f"sms3d train-pose: warning: {deprecation_message(EDGE_TOLERANCE_FLAG, instead)}", file=sys.stderr)
    return read_recipe(args.recipe or SHIPPED_RECIPE, [*overrides, *parse_set(args.set)], epochs=args.epochs,
                       seed=args.seed, device=args.device, progress=not args.quiet,
                       time_limit_s=None if args.time_limit_min is None else args.time_limit_min * 60.0)


def _samples(
    data: str | None, n: int, seed: int, model_ids: Sequence[int] | None, cache: Path | None, label: str,
    procedural: int = 0, camera_model: bool = False,
):  # fmt: skip
    from perception.baselines.point_transformer.data import load_samples, save_samples
    from perception.baselines.point_transformer.synthetic_views import (
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


def _edge_tolerance_mm(args: argparse.Namespace) -> float:
    return getattr(args, _dest(EDGE_TOLERANCE_FLAG)) or 0.0


def _check_data_sources(args: argparse.Namespace, recipe) -> None:
    """The recipe's data entries and the data flags agree: ``PerceptionConfigError`` naming the
    entry or flag that applies only to another source of clouds."""
    scene_only = (("data.add_synthetic", recipe.data.add_synthetic), (EDGE_TOLERANCE_FLAG, _edge_tolerance_mm(args)),
                  ("net.depth_smoothing_px", recipe.net.depth_smoothing_px))
    for name, given in scene_only:
        if given and not args.scenes:
            raise PerceptionConfigError(name, "needs --scenes")
    renders_views = bool(recipe.data.add_synthetic) if args.scenes else not (args.data or args.val_data)
    if recipe.data.camera_model and not renders_views:
        raise PerceptionConfigError("data.camera_model", "applies to rendered views: with --scenes set "
                                    "data.add_synthetic; drop --data / --val-data (their views were rendered already)")
    if not args.scenes:
        return
    if args.masks == "oracle":
        for name, given in scene_only[1:]:
            if given:
                raise PerceptionConfigError(name, "cuts a detector's clouds; needs --masks shipped or a checkpoint")
    elif recipe.data.cap_only:
        raise PerceptionConfigError("data.cap_only", "needs --masks oracle (detectors find whole mushrooms)")


def _scene_samples(args: argparse.Namespace, recipe, detector, split: str, seed: int) -> list:
    """Per-instance samples of every ``--scenes`` folder's ``split``, cut out by ``detector``'s
    masks (None: the renderer's) as the pipeline will cut them."""
    from perception.baselines.point_transformer.data import (
        samples_from_detections,
        samples_from_scenes,
    )

    if detector is None:
        return [s for root in args.scenes
                for s in samples_from_scenes(root, split, cap_only=recipe.data.cap_only, seed=seed)]
    from perception.pipeline import PosePipeline

    # The pipeline's own cut, without a network: the clouds are taken as it will take them.
    edge_mm = _edge_tolerance_mm(args)
    cut = PosePipeline(None, detector=None,  # type: ignore[arg-type]
                       edge_tolerance_m=edge_mm / 1000.0 if edge_mm > 0 else None,
                       depth_smoothing_px=recipe.net.depth_smoothing_px)
    return [s for root in args.scenes
            for s in samples_from_detections(root, split, detector, seed=seed, progress=not args.quiet,
                                             cloud_pixels=cut.cloud_pixels)]


def cmd_train(args: argparse.Namespace) -> int:
    import torch

    from generator.run_folder import RunFolderError
    from perception.baselines.point_transformer.data import PointCloudPoseDataset
    from perception.baselines.point_transformer.pose_net import PoseNet, load_backbone, load_weights
    from perception.baselines.point_transformer.train import train
    from perception.detection.load import load_detector

    torch.set_num_threads(args.threads)
    try:  # every setting and file named, checked before minutes of rendering or cutting
        check_out(args.out, args.resume)
        recipe = _recipe(args)
        _check_data_sources(args, recipe)
        detector = None
        if args.scenes:
            if args.masks != "oracle":
                with flag_errors("--masks"):
                    detector = load_detector(args.masks)
            check_datasets("--scenes", args.scenes)
        for flag, path, load in (("--init", args.init, load_weights),
                                 ("--init-backbone", args.init_backbone, load_backbone)):
            if path is not None:
                with flag_errors(flag):
                    load(PoseNet(recipe.net), path)
    except (PerceptionConfigError, RunFolderError) as exc:
        print(f"sms3d train-pose: error: {exc}", file=sys.stderr)
        return 2
    data, cache = recipe.data, Path(args.cache) if args.cache else None
    if args.scenes:
        train_s = _scene_samples(args, recipe, detector, "train", args.seed)
        val_s = _scene_samples(args, recipe, detector, "val", args.seed + 1)
        if data.add_synthetic:
            train_s = train_s + _samples(None, data.add_synthetic, args.seed * 1000 + 1, data.model_ids, cache, "train",
                                         data.procedural_models, data.camera_model)
        print(f"training on {len(train_s)} instances, validating on {len(val_s)}", file=sys.stderr)
    else:
        train_s = _samples(args.data, data.num_train, args.seed * 1000 + 1, data.model_ids, cache, "train",
                           data.procedural_models, data.camera_model)
        val_s = _samples(args.val_data, data.num_val, args.seed * 1000 + 2, data.model_ids, cache, "val", 0,
                         data.camera_model)
    net, cfg = recipe.net, recipe.train
    tr = PointCloudPoseDataset(train_s, net.num_points, net.use_rgb, cfg.augment, seed=args.seed)
    va = PointCloudPoseDataset(val_s, net.num_points, net.use_rgb, None, seed=args.seed + 1)
    t = time.perf_counter()
    try:
        _, rows = train(net, cfg, tr, va, args.out, overwrite=args.overwrite, init=args.init,
                        init_backbone=args.init_backbone)
    except (CheckpointMismatchError, CheckpointFormatError, FileNotFoundError, RunFolderError) as exc:
        print(f"sms3d train-pose: error: {exc}", file=sys.stderr)
        return 2
    best = min(rows, key=lambda r: r["val_loss"]) if rows else {}
    print(json.dumps({"train_time_s": time.perf_counter() - t, "epochs": len(rows), "best": best}, indent=2))
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    import torch

    from perception.baselines.point_transformer.data import (
        PointCloudPoseDataset,
        samples_from_scenes,
    )
    from perception.baselines.point_transformer.estimator import default_weights_path
    from perception.baselines.point_transformer.pose_net import load_checkpoint
    from perception.baselines.point_transformer.train import evaluate

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


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``train-pose`` and ``eval-pose`` to ``subparsers``."""
    from perception.baselines.point_transformer.config import TrainConfig

    p = subparsers.add_parser(
        "train-pose", help="train the point network (the paper's Point Transformer, a baseline) from a recipe",
        description="Train the point network. How it learns comes from the recipe (--recipe, --set); the "
                    "flags say what the run is: its folder, its data, where it starts and how long it runs.")
    run_folder_flags(p)
    p.add_argument("--recipe", metavar="FILE",
                   help="YAML recipe: sections net, train (and train.augment) and data "
                        "(default: the shipped network's, perception/baselines/point_transformer/recipe.yml)")
    p.add_argument("--set", nargs="+", action="extend", default=[], metavar="KEY=VALUE",
                   help="replace recipe entries, e.g. train.lr=3e-4 net.num_points=1024 data.model_ids=[0,1] "
                        "(values read as YAML; may be repeated)")
    p.add_argument("--scenes", nargs="+", metavar="DATASET",
                   help="train on the clouds of these `sms3d generate` datasets (their train and val splits) "
                        "instead of rendered single-mushroom views")
    p.add_argument("--masks", default="oracle",
                   help="with --scenes: whose masks cut out each mushroom's points: 'oracle' (the renderer's, default), "
                        "'shipped' (the shipped RGB-D segmenter's, matched to the truth by IoU >= 0.5) or a detector "
                        "checkpoint")
    p.add_argument("--data", metavar="NPZ",
                   help="training samples (perception.baselines.point_transformer.data format) instead of rendering")
    p.add_argument("--val-data", metavar="NPZ", help="validation samples, as --data")
    p.add_argument("--cache", metavar="DIR", help="folder to keep rendered views in as .npz, reused by later runs")
    p.add_argument("--init", metavar="CHECKPOINT",
                   help="start from this checkpoint's weights (fine-tune; the recipe's network shape)")
    p.add_argument("--init-backbone", metavar="CHECKPOINT",
                   help="start from this checkpoint's backbone and hidden head layer; a fresh output layer "
                        "(e.g. another net.head)")
    p.add_argument("--epochs", type=int, default=TrainConfig.epochs,
                   help="epochs to train (default %(default)s; more extend a finished run)")
    p.add_argument("--time-limit-min", type=float, metavar="MIN",
                   help="stop after the epoch that passes this many minutes (resumable)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the weights, batches, augmentation and rendered views (default %(default)s)")
    p.add_argument("--device", default="cpu", help="'cpu' (default) or 'cuda[:i]'")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads (default %(default)s)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    for flag, (_, kwargs) in DEPRECATED_FLAGS.items():  # hidden; they warn (_recipe)
        p.add_argument(flag, dest=_dest(flag), default=None, help=argparse.SUPPRESS, **kwargs)
    p.add_argument(EDGE_TOLERANCE_FLAG, dest=_dest(EDGE_TOLERANCE_FLAG), type=millimetres, default=None,
                   help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_train)

    e = subparsers.add_parser("eval-pose", help="evaluate a point-network checkpoint (default: its shipped weights)")
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
