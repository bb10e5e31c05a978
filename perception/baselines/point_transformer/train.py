"""Training and evaluation loops for :class:`~perception.baselines.point_transformer.pose_net.PoseNet`.

Adam (lr 1e-4 by default, as in the SMS3D paper) with ReduceLROnPlateau on the validation
loss, batch 32, label-preserving augmentation, validation every epoch, an atomic checkpoint
every epoch (``last.pt``, and ``train_state.pt`` with the weights and optimiser/scheduler/RNG
state for resuming) and of the best validation loss (``best.pt``), a CSV log and a tqdm bar.
Metrics are mean/median geodesic error and stem-axis error in degrees.
"""

from __future__ import annotations

import csv
import random
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset
from tqdm import tqdm

from generator.run_folder import open_run_folder
from perception.baselines.point_transformer.config import TrainConfig
from perception.baselines.point_transformer.data import PointCloudPoseDataset
from perception.baselines.point_transformer.metrics import PoseMetrics, errors_deg, summarize
from perception.baselines.point_transformer.pose_net import (
    PoseNet,
    PoseNetConfig,
    load_backbone,
    load_checkpoint,
    load_weights,
    save_checkpoint,
)
from perception.pose.rotations import rotation_loss
from perception.run_files import atomic_torch_save, read_torch_file, say_resumed

#: Settings a rerun may change and still resume: they extend or cut short a run, or say where
#: and how visibly it runs, not what it computes.
RESUMABLE_CHANGES = ("epochs", "time_limit_s", "device", "num_workers", "progress")

CSV_FIELDS = (
    "epoch", "lr", "train_loss", "val_loss", "val_mean_geodesic_deg", "val_median_geodesic_deg",
    "val_mean_axis_deg", "val_median_axis_deg", "epoch_s",
)  # fmt: skip


def seed_everything(seed: int) -> None:
    """Seed Python's and torch's global generators (NumPy draws use explicit Generators)."""
    random.seed(seed)
    torch.manual_seed(seed)


def _loader(ds: Dataset, batch_size: int, shuffle: bool, seed: int, workers: int) -> DataLoader:
    g = torch.Generator()
    g.manual_seed(seed)
    return DataLoader(ds, batch_size=batch_size, shuffle=shuffle, generator=g, num_workers=workers, drop_last=False)


@torch.no_grad()
def evaluate(
    model: PoseNet, dataset: Dataset, batch_size: int = 64, device: str = "cpu", loss: str = "geodesic"
) -> tuple[float, PoseMetrics, np.ndarray, np.ndarray, np.ndarray]:
    """Loss and metrics of ``model`` on ``dataset``; also per-sample geodesic/axis errors (deg)
    and the dataset indices they belong to."""
    model.eval()
    losses, gs, axs, idxs = [], [], [], []
    for x, R, idx in _loader(dataset, batch_size, False, 0, 0):
        pred = model(x.to(device))
        R = R.to(device)
        losses.append(float(rotation_loss(pred, R, loss)) * len(x))
        g, a = errors_deg(pred, R)
        gs.append(g)
        axs.append(a)
        idxs.append(idx.numpy())
    g, a = np.concatenate(gs), np.concatenate(axs)
    return sum(losses) / len(g), summarize(g, a), g, a, np.concatenate(idxs)


def train(
    net_config: PoseNetConfig,
    cfg: TrainConfig,
    train_set: PointCloudPoseDataset,
    val_set: PointCloudPoseDataset,
    out_dir: str | Path,
    overwrite: bool = False,
    on_epoch: Callable[[dict[str, float]], None] | None = None,
    init: str | Path | None = None,
    init_backbone: str | Path | None = None,
) -> tuple[PoseNet, list[dict[str, float]]]:
    """Train and return ``(best model in eval mode, per-epoch log rows)``.

    ``out_dir`` records the run's settings (``run_settings.json``: both configs, ``init``,
    ``init_backbone`` and the data's checksums). Rerun with the same settings (``RESUMABLE_CHANGES``
    aside), training continues from ``train_state.pt``; other settings raise
    :class:`~generator.run_folder.RunFolderError` naming them, unless ``overwrite``, which starts
    anew. Writes ``last.pt``, ``best.pt``, ``train_state.pt`` and ``log.csv`` in ``out_dir``.

    With ``init``, training starts from the weights of that checkpoint (fine-tuning; its network
    must have ``net_config``'s shape, else :class:`CheckpointMismatchError`, while its input
    fields such as ``depth_smoothing_px`` may differ: the saved network has ``net_config``'s); a resumed run
    ignores it. With ``init_backbone``, only that checkpoint's backbone and hidden head layer are
    loaded (:func:`~perception.baselines.point_transformer.pose_net.load_backbone`): the way to change the rotation head.
    """
    seed_everything(cfg.seed)
    device = torch.device(cfg.device)
    model = PoseNet(net_config).to(device)
    if init is not None:
        load_weights(model, init)
    if init_backbone is not None:
        load_backbone(model, init_backbone)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(
        opt, mode="min", factor=cfg.plateau_factor, patience=cfg.plateau_patience, min_lr=cfg.min_lr
    )
    settings = {**net_config.to_dict(), **cfg.to_dict(), "init": None if init is None else str(init),
                "init_backbone": None if init_backbone is None else str(init_backbone),
                "train_data": train_set.checksum(), "val_data": val_set.checksum()}
    run = open_run_folder(out_dir, settings, overwrite=overwrite, may_change=RESUMABLE_CHANGES)
    out = run.path
    start_epoch, best, rows = 0, float("inf"), []
    best_path, log_path, state_path = out / "best.pt", out / "log.csv", out / "train_state.pt"
    if run.resumed and state_path.is_file():
        state = read_torch_file(state_path, "pose training state")
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        sched.load_state_dict(state["scheduler"])
        start_epoch, best, rows = state["epoch"] + 1, state["best"], state["rows"]
        torch.set_rng_state(state["torch_rng"])
        random.setstate(state["python_rng"])
        say_resumed(out, start_epoch, cfg.epochs)
    loader = _loader(train_set, cfg.batch_size, True, cfg.seed, cfg.num_workers)
    t_start = time.perf_counter()
    for epoch in range(start_epoch, cfg.epochs):
        t0 = time.perf_counter()
        if hasattr(train_set, "set_epoch"):
            train_set.set_epoch(epoch)
        loader.generator.manual_seed(cfg.seed * 100003 + epoch)
        model.train()
        total, n = 0.0, 0
        bar = tqdm(loader, desc=f"epoch {epoch + 1}/{cfg.epochs}", disable=not cfg.progress, leave=False)
        for x, R, _ in bar:
            x, R = x.to(device), R.to(device)
            loss = rotation_loss(model(x), R, cfg.loss)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(x)
            n += len(x)
            bar.set_postfix(loss=f"{total / n:.4f}")
        val_loss, m, *_ = evaluate(model, val_set, device=str(device), loss=cfg.loss)
        sched.step(val_loss)
        row = {
            "epoch": epoch + 1, "lr": opt.param_groups[0]["lr"], "train_loss": total / max(n, 1),
            "val_loss": val_loss, "val_mean_geodesic_deg": m.mean_geodesic_deg,
            "val_median_geodesic_deg": m.median_geodesic_deg, "val_mean_axis_deg": m.mean_axis_deg,
            "val_median_axis_deg": m.median_axis_deg, "epoch_s": time.perf_counter() - t0,
        }  # fmt: skip
        rows.append(row)
        # The loss is dominated by yaw, which a round cap hides; "axis" keeps what a picker uses.
        score = val_loss if cfg.select_by == "loss" else m.mean_axis_deg
        if score < best:
            best = score
            save_checkpoint(best_path, model, {"epoch": epoch + 1, "val": m.as_dict(), "val_loss": val_loss})
        save_checkpoint(out / "last.pt", model, {"epoch": epoch + 1, "val": m.as_dict(), "val_loss": val_loss})
        # What resuming reads, the weights included: one file, so that a kill between two writes
        # cannot pair one epoch's weights with another's optimiser.
        atomic_torch_save(
            {
                "model": model.state_dict(), "optimizer": opt.state_dict(), "scheduler": sched.state_dict(),
                "epoch": epoch, "best": best, "rows": rows, "torch_rng": torch.get_rng_state(),
                "python_rng": random.getstate(),
            },  # fmt: skip
            state_path,
        )
        _write_csv(log_path, rows)
        if cfg.progress:
            tqdm.write(
                f"epoch {epoch + 1}: train {row['train_loss']:.4f} val {val_loss:.4f} "
                f"geo {m.mean_geodesic_deg:.2f}° axis {m.mean_axis_deg:.2f}° lr {row['lr']:.1e}"
            )
        if on_epoch is not None:
            on_epoch(row)
        if cfg.time_limit_s is not None and time.perf_counter() - t_start > cfg.time_limit_s:
            break
    best_model, _ = load_checkpoint(best_path, net_config, map_location=device) if best_path.exists() else (model, {})
    return best_model.eval(), rows


def _write_csv(path: Path, rows: list[dict[str, float]]) -> None:
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        w.writerows(rows)
    tmp.replace(path)
