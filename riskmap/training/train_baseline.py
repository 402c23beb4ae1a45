"""`riskmap train-baseline KIND`: behaviour cloning of the CNN, CNN-LSTM and RvS-G baselines.

Same demonstrations, same episode split (`riskmap.training.train.split_episodes`) and the same ego-pose
augmentation as the risk-map planner's training; the loss is the mean L2 distance between the
predicted and the recorded 12 waypoints (ADE). Writes RUN/log.csv, RUN/last.* (weights,
optimizer, progress: for --resume) and RUN/best.* (lowest validation ADE).
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, Subset

from rasterize.errors import InputError
from rasterize.frames import ego_from_world, ego_pose
from rasterize.raster import channels
from riskmap.data.dataset import DemoDataset, PerturbedEgo
from riskmap.infra.atomic import atomic_write
from riskmap.infra.checkpoint import read_sidecar, save_checkpoint
from riskmap.infra.rundir import lock_out_dir, refuse_unless_resume
from riskmap.planner.bc import CHECKPOINT_KIND, BCConfig, BCNet, bc_inputs
from riskmap.training.config import BaselineTrainConfig
from riskmap.training.train import (
    dataset_sidecar,
    raster_for,
    resolve_goal_variance,
    same_settings,
    split_episodes,
)


class BCWindows(Dataset):
    """Baseline samples of a DemoDataset: frames [K, C', H, W], speed [K], future [12, 2] (ego, m).

    With `augment`, the ego's current pose is perturbed as in `riskmap.data.dataset.PerturbedEgo`, drawn
    from (seed, epoch, index) only, so a resumed run sees the same samples.
    """

    def __init__(self, base: DemoDataset, config: BCConfig, augment: tuple[float, float, float] | None,
                 seed: int = 0):
        self.base, self.config = base, config
        # Scenes come from the risk-map planner's own augmentation (same draws), or as recorded.
        self.scenes = base if augment is None else PerturbedEgo(base, seed, *augment)

    def set_epoch(self, epoch: int) -> None:
        if isinstance(self.scenes, PerturbedEgo):
            self.scenes.set_epoch(epoch)

    def __len__(self) -> int:
        return len(self.base)

    def __getitem__(self, index: int) -> dict:
        scene = self.scenes.scene(index)
        frames, speeds = bc_inputs(scene, self.config, self.base.raster_config)
        origin, heading = ego_pose(scene)
        future = ego_from_world(scene.ego_future_xy(), origin, heading).astype(np.float32)
        return {"frames": torch.from_numpy(frames), "speed": torch.from_numpy(speeds),
                "future": torch.from_numpy(future)}


def displacement(pred: torch.Tensor, future: torch.Tensor) -> torch.Tensor:
    """Per-waypoint L2 error [B, 12] of pred and future [B, 12, 2]."""
    return torch.linalg.vector_norm(pred - future, dim=-1)


def _validate(model: BCNet, loader: DataLoader) -> dict:
    model.eval()
    errors = []
    with torch.no_grad():
        for batch in loader:
            errors.append(displacement(model(batch["frames"], batch["speed"]), batch["future"]))
    err = torch.cat(errors)
    return {"val_ade_m": float(err.mean()), "val_fde_m": float(err[:, -1].mean())}


def _sidecar(config: BaselineTrainConfig, bc: BCConfig, dataset: DemoDataset, data: dict,
             metrics: dict, epoch: int, best: dict) -> dict:
    return {"bc": bc.to_dict(), "raster": dataset.raster_config.to_dict(), "train": asdict(config),
            "dataset": data, "epoch": epoch, "metrics": metrics, "best": best}


def train_baseline(config: BaselineTrainConfig, resume: bool = False, progress: bool = True) -> dict:
    """Train one baseline; returns the best epoch's metrics."""
    from tqdm import tqdm

    out = Path(config.out)
    refuse_unless_resume(out, "a training run", "last.json", resume)
    torch.manual_seed(config.seed)
    dataset = DemoDataset(config.data, raster=raster_for(config.data, config.predict_s))
    train_idx, val_idx = split_episodes(dataset, config.val_fraction, config.val_groups)
    if config.max_windows:
        train_idx = train_idx[: config.max_windows]
        val_idx = val_idx[: max(1, config.max_windows // 4)]
    bc = BCConfig(kind=config.kind, in_channels=len(channels(dataset.raster_config)),
                  history_frames=config.history_frames,
                  goal_variance=resolve_goal_variance(None, dataset))
    model = BCNet(bc)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    start_epoch, best = 0, {"val_ade_m": math.inf}
    if resume and (out / "last.json").exists():
        previous = read_sidecar(out / "last", kind=CHECKPOINT_KIND)
        if not same_settings(previous["train"], config):
            raise InputError(f"--out {out} was trained with other settings; resume with the same "
                             "flags (only --epochs may change) or choose another --out")
        from safetensors.torch import load_file

        model.load_state_dict(load_file(str(out / "last.safetensors")))
        optimizer.load_state_dict(torch.load(out / "last_optimizer.pt", weights_only=True))
        start_epoch, best = previous["epoch"] + 1, previous["best"]
    lock_out_dir(out)   # one writer per run directory (creates it)
    data = dataset_sidecar(dataset, train_idx, val_idx)
    augment = (config.augment_probability, config.augment_heading_deg, config.augment_lateral_m)
    train_set = BCWindows(dataset, bc, augment, config.seed)
    val_loader = DataLoader(Subset(BCWindows(dataset, bc, None), val_idx), batch_size=config.batch_size)
    log_path = out / "log.csv"
    fields = ["epoch", "train_ade_m", "val_ade_m", "val_fde_m", "seconds"]
    if start_epoch == 0:
        log_path.write_text(",".join(fields) + "\n")
    for epoch in range(start_epoch, config.epochs):
        started = time.perf_counter()
        model.train()
        train_set.set_epoch(epoch)
        order = torch.randperm(len(train_idx),
                               generator=torch.Generator().manual_seed(config.seed * 100003 + epoch))
        loader = DataLoader(Subset(train_set, [train_idx[i] for i in order]),
                            batch_size=config.batch_size)
        losses = []
        bar = tqdm(loader, desc=f"{config.kind} epoch {epoch + 1}/{config.epochs}",
                   disable=not progress, leave=False)
        for batch in bar:
            loss = displacement(model(batch["frames"], batch["speed"]), batch["future"]).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            losses.append(loss.item())
            bar.set_postfix(ade=f"{np.mean(losses):.2f}")
        metrics = {"train_ade_m": float(np.mean(losses)), **_validate(model, val_loader)}
        metrics["seconds"] = round(time.perf_counter() - started, 1)
        with log_path.open("a", newline="") as f:
            csv.DictWriter(f, fields).writerow({"epoch": epoch, **metrics})
        if metrics["val_ade_m"] < best["val_ade_m"]:
            best = {"epoch": epoch, **metrics}
            save_checkpoint(out / "best", model, _sidecar(config, bc, dataset, data, metrics, epoch, best),
                            kind=CHECKPOINT_KIND)
        # Progress last, so that a run killed mid-save resumes from the previous epoch.
        atomic_write(out / "last_optimizer.pt", lambda f: torch.save(optimizer.state_dict(), f))
        save_checkpoint(out / "last", model, _sidecar(config, bc, dataset, data, metrics, epoch, best),
                        kind=CHECKPOINT_KIND)
        if progress:
            print(f"{config.kind} epoch {epoch + 1}/{config.epochs}: " +
                  ", ".join(f"{k} {v:.3f}" for k, v in metrics.items()), flush=True)
    return best
