"""Training the axis CNN (``axis_cnn``) on crops cut out by a stage-1 detector's masks.

``crops_from_detections`` renders nothing: it reads generated scenes (``sms3d generate``), runs
the detector, matches its masks to the ground truth (``detection.detector.matched_detections``)
and crops each matched mushroom (``depth_crops``), labelled with its true stem axis in the
crop's ray frame. The crops of a dataset split are cached in one ``.npz`` (``generator.files.save_npz_atomic``:
written atomically; remade when the split's scenes (by the checksums the generator recorded),
the detector's weights or the crop layout change).

``train_axis_cnn`` fits the network on the training splits' crops with a loss between predicted
and true axes (``axis_loss``), one random quarter turn and mirror (``dihedral``) per batch,
AdamW, a linear warm-up and cosine decay over the whole run; after every epoch it scores the
validation splits (mean axis error, 8 dihedral views) and writes ``last.pt`` (resumable:
weights, optimiser, epoch), ``best.pt`` (the network with the lowest validation error, in the
shipped format) and ``log.csv``, all atomically. The output folder records the run's settings
(``generator.run_folder``): a rerun with the same ones resumes from ``last.pt`` (more ``epochs``
or another time limit extend it; the cosine schedule then spans the new length, a warm restart), other ones are refused unless ``overwrite``. Batches are drawn
from a generator seeded by ``seed`` and the epoch, so a resumed run draws what the uninterrupted
one would have.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from generator.files import read_npz_made_with, save_npz_atomic
from generator.run_folder import open_run_folder
from perception.choices import AXIS_LOSSES
from perception.errors import NoEstimate, PerceptionConfigError
from perception.pose.axis_cnn import (
    AxisCNN,
    AxisCNNConfig,
    dihedral,
    load_axis_cnn,
    predict_axes,
    save_axis_cnn,
)
from perception.pose.depth_crops import (
    CROP_CHANNELS,
    CROP_MARGIN,
    CROP_PAD_PX,
    CROP_SIZE,
    crop_around_mask,
)
from perception.pose.widen import widen_axis_cnn
from perception.run_files import (
    atomic_torch_save,
    checksum,
    learning_rate,
    read_torch_file,
    say_resumed,
    write_log_csv,
)

#: Meta columns of a crop set.
META_COLUMNS = ("scene_id", "instance_id", "mask_iou", "visible_fraction", "tilt_deg", "cap_diameter_mm")
#: Settings a rerun may change and still resume: they extend or cut short a run, not redo it.
RESUMABLE_CHANGES = ("epochs", "time_limit_min")


@dataclass(frozen=True)
class AxisTrainConfig:
    """Optimisation settings (``sms3d train-axis-cnn`` flags of the same names)."""

    epochs: int = 60
    batch_size: int = 128
    lr: float = 2e-3
    weight_decay: float = 1e-4
    warmup_iters: int = 500
    seed: int = 0
    time_limit_min: float | None = None
    loss: str = "angle"

    def __post_init__(self) -> None:
        if self.loss not in AXIS_LOSSES:
            raise PerceptionConfigError("loss", f"must be one of {AXIS_LOSSES}, got {self.loss!r}")
        for name, least in (("epochs", 1), ("batch_size", 1), ("warmup_iters", 0)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < least:
                raise PerceptionConfigError(name, f"must be an int >= {least}, got {value!r}")
        for name, positive in (("lr", True), ("weight_decay", False)):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value) \
                    or value < 0 or (positive and value == 0):
                raise PerceptionConfigError(name, f"must be a finite number {'> 0' if positive else '>= 0'}, got {value!r}")
        limit = self.time_limit_min
        if limit is not None and (not isinstance(limit, (int, float)) or isinstance(limit, bool)
                                  or not np.isfinite(limit) or limit <= 0):
            raise PerceptionConfigError("time_limit_min", f"must be > 0 or None, got {self.time_limit_min!r}")


@dataclass
class CropSet:
    """Crops ``(N, C, S, S)`` float16, ray-frame axes ``(N, 3)`` float32 and ``meta (N, 6)``
    (``META_COLUMNS``)."""

    crops: np.ndarray
    axes: np.ndarray
    meta: np.ndarray

    def __len__(self) -> int:
        return len(self.axes)

    def checksum(self) -> str:
        """What a run records of its crops (see ``run_files.checksum``)."""
        return checksum(self.crops, self.axes, self.meta)

    @classmethod
    def concatenate(cls, sets: list[CropSet]) -> CropSet:
        return cls(*(np.concatenate([getattr(s, f.name) for s in sets]) for f in dataclasses.fields(cls)))


def crops_from_detections(root: str | Path, split: str | None, detector: Any, progress: bool = False) -> CropSet:
    """The crops of every mushroom the ``detector`` finds (and matches) in a generated dataset's
    ``split``; see the module doc."""
    from generator.dataset.readers import read_scene_files, scene_indices
    from generator.dataset.writer import scene_dirname
    from generator.geometry import tilt_angle
    from perception.detection.detector import matched_detections

    root = Path(root)
    indices = scene_indices(root, split)
    if progress:
        from tqdm import tqdm

        indices = tqdm(indices, desc=f"crops of {root.name}/{split}", unit="scene")
    crops, axes, meta = [], [], []
    for index in indices:
        s = read_scene_files(root / scene_dirname(index), verify=False)
        camera_from_world = np.asarray(s.world_from_camera)[:3, :3].T
        visible = {a["instance_id"]: a.get("visible_fraction", 0.0) for a in s.annotations if a["category_id"] == 2}
        instances = {inst["id"]: inst for inst in s.record["instances"]}
        k = s.intrinsics
        for det, iid, iou in matched_detections(detector.detect(s.rgb, s.depth), s.labels_mushroom):
            try:
                c = crop_around_mask(s.rgb, s.depth, det.mask, k.fx, k.fy, k.cx, k.cy)
            except NoEstimate:
                continue
            rotation = np.asarray(instances[iid]["rotation"], dtype=np.float64)
            crops.append(c.image.astype(np.float16))
            axes.append(c.ray_from_camera @ camera_from_world @ rotation[:, 2])
            meta.append((index, iid, iou, visible.get(iid, 0.0), np.degrees(tilt_angle(rotation)),
                         1000.0 * instances[iid]["cap_diameter"]))
    empty = np.zeros((0, CROP_CHANNELS, CROP_SIZE, CROP_SIZE), np.float16)
    return CropSet(np.stack(crops) if crops else empty, np.array(axes, np.float32).reshape(-1, 3),
                   np.array(meta, np.float64).reshape(-1, len(META_COLUMNS)))


def cached_crops(root: str | Path, split: str, detector: Any, detector_id: str, cache: str | Path | None,
                 progress: bool = False) -> CropSet:
    """:func:`crops_from_detections`, read from ``cache`` when it holds the crops of the same
    scenes, split and detector (``detector_id``: e.g. its weights' hash), else made and saved.

    The scenes are known by their content (``dataset_checksum``), not their folder: a dataset
    regenerated at the same path gets new crops."""
    from generator.dataset.readers import dataset_checksum

    made_with = {"scenes": dataset_checksum(root, split), "split": split, "detector": detector_id,
                 "crop": [CROP_SIZE, CROP_CHANNELS, CROP_MARGIN, CROP_PAD_PX]}
    path = None if cache is None else Path(cache) / f"axis_crops_{Path(root).name}_{split}.npz"
    if path is not None:
        arrays = read_npz_made_with(path, made_with)  # None: missing, cut short or other settings
        if arrays is not None:
            return CropSet(**arrays)
    crop_set = crops_from_detections(root, split, detector, progress)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        save_npz_atomic(path, {"crops": crop_set.crops, "axes": crop_set.axes, "meta": crop_set.meta}, made_with)
    return crop_set


def axis_loss(predicted: torch.Tensor, target: torch.Tensor, kind: str = "angle") -> torch.Tensor:
    """The mean loss between unit axes ``predicted (B, 3)`` and ``target (B, 3)``.

    ``"cosine"``: ``1 - cos``, which near zero is half the squared angle, so it weighs a crop by
    its error and pulls an uncertain estimate towards the mean of the plausible axes. ``"angle"``:
    the angle in radians (``atan2(|p x t|, p . t)``, smoothed at zero), the quantity the mean
    axis error measures, which pulls it towards their median instead."""
    dot = (predicted * target).sum(-1)
    if kind == "cosine":
        return (1.0 - dot).mean()
    if kind == "angle":
        # the 1e-12 keeps the gradient of |p x t| finite where the axes agree
        sine = torch.linalg.cross(predicted, target).pow(2).sum(-1).add(1e-12).sqrt()
        return torch.atan2(sine, dot).mean()
    raise PerceptionConfigError("loss", f"must be one of {AXIS_LOSSES}, got {kind!r}")


def axis_errors_deg(model: AxisCNN, crop_set: CropSet) -> np.ndarray:
    """Per crop, the angle (degrees) between the estimated (8 views) and the true axis."""
    predicted = predict_axes(model, torch.from_numpy(crop_set.crops))
    cos = (predicted * torch.from_numpy(crop_set.axes)).sum(-1).clamp(-1.0, 1.0)
    return torch.rad2deg(torch.arccos(cos)).numpy()


def train_axis_cnn(train: CropSet, val: CropSet, out: str | Path, config: AxisTrainConfig | None = None,
                   net: AxisCNNConfig | None = None, overwrite: bool = False, progress: bool = True,
                   extra: dict[str, Any] | None = None, init: str | Path | None = None) -> dict[str, Any]:
    """Fit an axis CNN (see the module doc); returns the best epoch's metrics. ``init`` starts
    from a saved network's weights instead of the upright prior; a ``net`` wider than it widens
    it first, keeping its function (``widen.widen_axis_cnn``). ``extra`` (JSON values, e.g. the
    command's dataset folders) is recorded with the settings and in ``best.pt``.

    Raises:
        PerceptionConfigError: too few crops for a batch, or no validation crops.
        FileNotFoundError, CheckpointFormatError: ``init`` or ``out``'s ``last.pt`` unreadable.
        generator.run_folder.RunFolderError: ``out`` holds a run with other settings (each named)
            and not ``overwrite``.
    """
    config = config or AxisTrainConfig()
    if len(train) < config.batch_size:
        raise PerceptionConfigError("batch_size", f"{config.batch_size} is more than the {len(train)} training crops")
    if len(val) == 0:
        raise PerceptionConfigError("val", "no validation crops")
    torch.manual_seed(config.seed)
    if init is None:
        model = AxisCNN(net or AxisCNNConfig())
    else:
        model = load_axis_cnn(init)[0]
        if net is not None and (net.width, net.hidden) != (model.config.width, model.config.hidden):
            model = widen_axis_cnn(model, net.width, net.hidden, seed=config.seed)
    recorded = {"init": None if init is None else str(init), **(extra or {})}
    settings = {**dataclasses.asdict(config), **dataclasses.asdict(model.config), **recorded,
                "train_crops": train.checksum(), "val_crops": val.checksum()}
    run = open_run_folder(out, settings, overwrite=overwrite, may_change=RESUMABLE_CHANGES)
    out = run.path
    model.train()
    optimiser = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    rows: list[dict[str, Any]] = []
    start_epoch, best = 0, {"val_mean_axis_deg": float("inf")}
    state_path = out / "last.pt"
    if run.resumed and state_path.is_file():
        state = read_torch_file(state_path, "axis-CNN training state")
        model.load_state_dict(state["model"])
        optimiser.load_state_dict(state["optimiser"])
        start_epoch, rows, best = state["epoch"], state["rows"], state["best"]
        say_resumed(out, start_epoch, config.epochs)
    crops, axes = torch.from_numpy(train.crops), torch.from_numpy(train.axes)
    steps = len(train) // config.batch_size
    total = config.epochs * steps
    deadline = None if config.time_limit_min is None else time.monotonic() + 60.0 * config.time_limit_min
    epochs = range(start_epoch, config.epochs)
    if progress:
        from tqdm import tqdm

        epochs = tqdm(epochs, desc="train-axis-cnn", unit="epoch", initial=start_epoch, total=config.epochs)
    for epoch in epochs:
        began = time.monotonic()
        model.train()
        draw = torch.Generator().manual_seed(config.seed * 100_003 + epoch)
        order = torch.randperm(len(train), generator=draw)
        losses = []
        for step in range(steps):
            for group in optimiser.param_groups:
                group["lr"] = learning_rate(config, epoch * steps + step, total)
            batch = order[step * config.batch_size:(step + 1) * config.batch_size]
            turns, mirror = int(torch.randint(4, (1,), generator=draw)), bool(torch.randint(2, (1,), generator=draw))
            x, target = dihedral(crops[batch].float(), axes[batch], turns, mirror)
            loss = axis_loss(model(x), target, config.loss)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            losses.append(loss.item())
        errors = axis_errors_deg(model, val)
        row = {"epoch": epoch + 1, "lr": learning_rate(config, (epoch + 1) * steps - 1, total),
               "train_loss": float(np.mean(losses)), "val_mean_axis_deg": float(errors.mean()),
               "val_median_axis_deg": float(np.median(errors)), "epoch_s": time.monotonic() - began}
        rows.append(row)
        if row["val_mean_axis_deg"] < best["val_mean_axis_deg"]:
            best = row
            save_axis_cnn(out / "best.pt", model, {"metrics": row, "train": dataclasses.asdict(config), **recorded})
        atomic_torch_save({"model": model.state_dict(), "optimiser": optimiser.state_dict(), "epoch": epoch + 1,
                           "rows": rows, "best": best}, state_path)
        write_log_csv(out / "log.csv", rows)
        if deadline is not None and time.monotonic() > deadline:
            break
    return best


__all__ = ["AxisTrainConfig", "CropSet", "META_COLUMNS", "axis_errors_deg", "axis_loss", "cached_crops", "crops_from_detections",
           "train_axis_cnn"]
