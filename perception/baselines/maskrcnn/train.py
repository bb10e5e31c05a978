"""Train a Mask R-CNN detector on a generated dataset's COCO files, with resumable checkpoints.

``train_detector`` writes into ``out``: ``last.pt`` (weights, optimiser, epoch: what resuming
reads), ``best.pt`` (the epoch with the best validation mask AP, or the last epoch without a
validation split), and ``log.csv``. Each file is replaced atomically, so a run killed at any
point resumes from its last finished epoch. The folder records the run's settings
(``generator.run_folder``): a rerun with the same ones resumes (more ``epochs`` extend it), other
ones are refused unless ``overwrite``.
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch
from torch.utils.data import DataLoader

from generator.dataset.readers import dataset_checksum
from generator.run_folder import open_run_folder
from perception.baselines.maskrcnn.config import DetectorTrainConfig
from perception.baselines.maskrcnn.model import (
    DetectorConfig,
    MaskRCNNDetector,
    build_maskrcnn,
    read_detector_checkpoint,
    save_detector,
)
from perception.detection.detector_data import CocoDetectionDataset, collate_detection
from perception.detection.detector_eval import evaluate_detector
from perception.errors import PerceptionConfigError
from perception.run_files import learning_rate, say_resumed, write_log_csv

#: Settings a rerun may change and still resume: more epochs extend a run.
RESUMABLE_CHANGES = ("epochs",)


def train_detector(root: str | Path, out: str | Path, config: DetectorConfig | None = None,
                   train: DetectorTrainConfig | None = None, overwrite: bool = False,
                   device: str = "cpu", progress: bool = True) -> list[dict[str, Any]]:
    """Train on ``root``'s train split; returns the per-epoch log (loss, validation AP/F1, time).

    Raises:
        PerceptionConfigError: the train split has no images.
        generator.run_folder.RunFolderError: ``out`` holds a run with other settings (each named)
            and not ``overwrite``.
    """
    config, train = config or DetectorConfig(), train or DetectorTrainConfig()
    torch.manual_seed(train.seed)
    dataset = CocoDetectionDataset(root, "train", config.category, augment=train.augment)
    if train.max_images is not None:
        dataset = torch.utils.data.Subset(dataset, range(min(train.max_images, len(dataset))))
    if len(dataset) == 0:
        raise PerceptionConfigError("root", f"{root}: the train split has no images")
    if train.passes_per_epoch > 1:
        dataset = torch.utils.data.ConcatDataset([dataset] * train.passes_per_epoch)
    has_val = _has_split(root, train.val_split) and bool(CocoDetectionDataset(root, train.val_split, config.category).images)

    model = build_maskrcnn(config, pretrained=train.pretrained).to(device)
    params = [p for p in model.parameters() if p.requires_grad]
    optimiser = torch.optim.AdamW(params, lr=train.lr, weight_decay=train.weight_decay)
    settings = {**asdict(config), **asdict(train), "data": str(Path(root).resolve()), "scenes": dataset_checksum(root)}
    run = open_run_folder(out, settings, overwrite=overwrite, may_change=RESUMABLE_CHANGES)
    out = run.path
    start_epoch, log, best_ap = 0, [], -1.0
    last = out / "last.pt"
    if run.resumed and last.is_file():
        state = read_detector_checkpoint(last)
        model.load_state_dict(state["model"])
        optimiser.load_state_dict(state["optimiser"])
        start_epoch, log, best_ap = state["epoch"], state["log"], state["best_ap"]
        torch.set_rng_state(state["rng"])
        say_resumed(out, start_epoch, train.epochs)

    generator = torch.Generator().manual_seed(train.seed)
    loader = DataLoader(dataset, batch_size=train.batch_size, shuffle=True, collate_fn=collate_detection,
                        generator=generator)
    iters_done = start_epoch * len(loader)
    for epoch in range(start_epoch, train.epochs):
        generator.manual_seed(train.seed * 100_003 + epoch)  # the same order whether resumed or not
        model.train()
        start, total, count = time.perf_counter(), 0.0, 0
        batches = loader
        if progress:
            from tqdm import tqdm
            batches = tqdm(loader, desc=f"train-detector epoch {epoch + 1}/{train.epochs}", unit="batch", file=sys.stderr)
        for images, targets in batches:
            for group in optimiser.param_groups:
                group["lr"] = learning_rate(train, iters_done, train.epochs * len(loader))
            losses = model([im.to(device) for im in images], [{k: v.to(device) for k, v in t.items()} for t in targets])
            loss = sum(losses.values())
            if not torch.isfinite(loss):
                raise FloatingPointError(f"non-finite training loss at epoch {epoch + 1} ({ {k: v.detach().item() for k, v in losses.items()} }); "
                                         "lower --lr")
            optimiser.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(params, 10.0)
            optimiser.step()
            iters_done += 1
            total, count = total + loss.detach().item(), count + 1
            if progress:
                batches.set_postfix(loss=f"{total / count:.3f}")
        row: dict[str, Any] = {"epoch": epoch + 1, "train_loss": total / count, "seconds": time.perf_counter() - start}
        if has_val:
            report = evaluate_detector(MaskRCNNDetector(model, config, device), root, train.val_split, config.category,
                                       score_threshold=config.score_threshold, max_images=train.max_val_images)
            model.train()
            row.update(val_mask_ap=report.mask.ap, val_mask_f1=report.mask.f1, val_box_ap=report.box.ap)
        log.append(row)
        score = row.get("val_mask_ap", float(epoch))
        extra = {"train": asdict(train), "log": log}
        if score >= best_ap:
            best_ap = score
            save_detector(out / "best.pt", model, config, extra)
        save_detector(last, model, config, {**extra, "optimiser": optimiser.state_dict(), "epoch": epoch + 1,
                                            "best_ap": best_ap, "rng": torch.get_rng_state()})
        write_log_csv(out / "log.csv", log)
        if progress:
            print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), file=sys.stderr)
    return log


def _has_split(root: str | Path, split: str | None) -> bool:
    return bool(split) and (Path(root) / f"coco_{split}.json").is_file()
