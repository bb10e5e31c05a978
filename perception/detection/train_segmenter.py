"""Train the RGB-D segmenter on generated datasets, resumably and within a time budget.

``train_segmenter`` writes into ``out``: ``last.pt`` (weights, optimiser, epoch, log: what
resuming reads), ``best.pt`` (the epoch with the best validation mask F1) and ``log.csv``; each
is replaced atomically, so a run killed at any point resumes from its last finished epoch. The
folder records the run's settings (``generator.run_folder``): a rerun with the same ones resumes
(more ``epochs`` or another time limit extend it; the cosine schedule then spans the new
length, a warm restart), other ones are refused unless ``overwrite``.
Losses: binary cross-entropy on the mushroom mask, CenterNet's penalty-reduced focal loss on
the centre heat (Zhou et al., "Objects as Points", 2019), L1 on the offsets.
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from torch.utils.data import DataLoader

from generator.dataset.readers import dataset_checksum
from generator.run_folder import open_run_folder
from perception.detection.rgbd_segmenter import (
    RGBDSegmenter,
    build_segmenter,
    read_segmenter_checkpoint,
    save_segmenter,
)
from perception.detection.segmenter_config import SegmenterConfig, SegmenterTrainConfig
from perception.detection.segmenter_data import SegmenterDataset, scene_folders
from perception.errors import PerceptionConfigError
from perception.run_files import learning_rate, say_resumed, write_log_csv

#: Settings a rerun may change and still resume: they extend or cut short a run, not redo it.
RESUMABLE_CHANGES = ("epochs", "time_limit_min")


def focal_centre_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """CenterNet's focal loss (alpha 2, beta 4), normalised by the number of centres."""
    p = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
    positive = target >= 1.0
    pos = -((1 - p) ** 2 * torch.log(p))[positive].sum()
    neg = -((1 - target) ** 4 * p**2 * torch.log(1 - p))[~positive].sum()
    return (pos + neg) / positive.sum().clamp(min=1)


def segmenter_losses(heads: torch.Tensor, mushroom: torch.Tensor, mask_weight: torch.Tensor, centre: torch.Tensor,
                     offset: torch.Tensor, offset_weight: torch.Tensor) -> dict[str, torch.Tensor]:
    mask = (F.binary_cross_entropy_with_logits(heads[:, 0], mushroom, reduction="none") * mask_weight).sum() \
        / mask_weight.sum().clamp(min=1)
    centre_loss = focal_centre_loss(heads[:, 1], centre)
    off = (F.l1_loss(heads[:, 2:], offset, reduction="none").sum(1) * offset_weight).sum() / offset_weight.sum().clamp(min=1)
    return {"mask": mask, "centre": centre_loss, "offset": off}


def validate(segmenter: RGBDSegmenter, roots: list[str | Path], max_images: int) -> dict[str, float]:
    """Mask F1 and AP on each root's ``val`` split (the first ``max_images``), averaged by image."""
    from perception.detection.detector_eval import evaluate_detector

    reports = [evaluate_detector(segmenter, root, "val", score_threshold=segmenter.score_threshold, max_images=max_images)
               for root in roots if (Path(root) / "coco_val.json").is_file()]
    reports = [r for r in reports if r.images]
    if not reports:
        return {}
    n = sum(r.images for r in reports)
    return {"val_mask_f1": sum(r.mask.f1 * r.images for r in reports) / n,
            "val_mask_ap": sum(r.mask.ap * r.images for r in reports) / n}


def train_segmenter(roots: list[str | Path], out: str | Path, config: SegmenterConfig | None = None,
                    train: SegmenterTrainConfig | None = None, overwrite: bool = False,
                    progress: bool = True) -> list[dict[str, Any]]:
    """Train on the ``train`` splits of ``roots``; returns the per-epoch log.

    Raises:
        PerceptionConfigError: no training scenes, or fewer than ``batch_size`` of them.
        generator.run_folder.RunFolderError: ``out`` holds a run with other settings (each named)
            and not ``overwrite``.
    """
    config, train = config or SegmenterConfig(), train or SegmenterTrainConfig()
    torch.manual_seed(train.seed)
    dataset = SegmenterDataset(scene_folders(roots, "train"), crop=train.crop, sigma=config.centre_sigma_px)
    if len(dataset) < train.batch_size:  # every batch is full (drop_last): there would be none
        raise PerceptionConfigError("batch_size", f"{train.batch_size} is more than the {len(dataset)} training images "
                                                  f"of {', '.join(map(str, roots))}; lower --batch-size")
    model = build_segmenter(config)
    optimiser = torch.optim.AdamW(model.parameters(), lr=train.lr, weight_decay=train.weight_decay)
    settings = {**asdict(train), **config.to_dict(), "data": [str(Path(r).resolve()) for r in roots],
                "scenes": [dataset_checksum(r) for r in roots]}
    run = open_run_folder(out, settings, overwrite=overwrite, may_change=RESUMABLE_CHANGES)
    out = run.path
    start_epoch, log, best = 0, [], -1.0
    last = out / "last.pt"
    if run.resumed and last.is_file():
        state = read_segmenter_checkpoint(last)
        model.load_state_dict(state["model"])
        optimiser.load_state_dict(state["optimiser"])
        start_epoch, log, best = state["epoch"], state["log"], state["best_f1"]
        torch.set_rng_state(state["rng"])
        say_resumed(out, start_epoch, train.epochs)
    generator = torch.Generator().manual_seed(train.seed)
    loader = DataLoader(dataset, batch_size=train.batch_size, shuffle=True, generator=generator, drop_last=True)
    total_iters = train.epochs * len(loader)
    began = time.perf_counter() - sum(r["seconds"] for r in log)
    for epoch in range(start_epoch, train.epochs):
        if train.time_limit_min is not None and time.perf_counter() - began > 60 * train.time_limit_min:
            if progress:
                print(f"train-segmenter: time limit of {train.time_limit_min} min reached after {epoch} epochs", file=sys.stderr)
            break
        generator.manual_seed(train.seed * 100_003 + epoch)  # the same order whether resumed or not
        model.train()
        start, sums, count = time.perf_counter(), {}, 0
        batches = loader
        if progress:
            from tqdm import tqdm
            batches = tqdm(loader, desc=f"train-segmenter epoch {epoch + 1}/{train.epochs}", unit="batch", file=sys.stderr)
        for i, (inputs, *targets) in enumerate(batches):
            for group in optimiser.param_groups:
                group["lr"] = learning_rate(train, epoch * len(loader) + i, total_iters)
            losses = segmenter_losses(model(inputs), *targets)
            loss = sum(losses.values())
            if not torch.isfinite(loss):
                raise FloatingPointError(f"non-finite training loss at epoch {epoch + 1}; lower --lr")
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            for k, v in losses.items():
                sums[k] = sums.get(k, 0.0) + v.item()
            count += 1
            if progress:
                batches.set_postfix(loss=f"{sum(sums.values()) / count:.3f}")
        row: dict[str, Any] = {"epoch": epoch + 1, "seconds": time.perf_counter() - start,
                               **{f"loss_{k}": v / count for k, v in sums.items()}}
        final = epoch + 1 == train.epochs
        if (epoch + 1) % train.val_every == 0 or final:
            row.update(validate(RGBDSegmenter(model, config), roots, train.max_val_images))
            model.train()
        log.append(row)
        extra = {"train": asdict(train), "log": log}
        if "val_mask_f1" in row and row["val_mask_f1"] >= best:
            best = row["val_mask_f1"]
            save_segmenter(out / "best.pt", model, config, extra)
        save_segmenter(last, model, config, {**extra, "optimiser": optimiser.state_dict(), "epoch": epoch + 1,
                                             "best_f1": best, "rng": torch.get_rng_state()})
        write_log_csv(out / "log.csv", log)
        if progress:
            print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), file=sys.stderr)
    if not (out / "best.pt").is_file():  # no validation split: the last epoch is the best known
        save_segmenter(out / "best.pt", model, config, {"train": asdict(train), "log": log})
    return log
