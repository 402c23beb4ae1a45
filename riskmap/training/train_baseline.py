"""`riskmap train-baseline KIND`: behaviour cloning of the CNN, CNN-LSTM and RvS-G baselines.

Same demonstrations, same episode split (`riskmap.training.train.split_episodes`) and the same ego-pose
augmentation as the risk-map planner's training; the loss is the mean L2 distance between the
predicted and the recorded 12 waypoints (ADE). Writes RUN/state.pt (everything --resume needs,
the epoch's one commit point: `riskmap.infra.training_run`), then from it RUN/log.csv, RUN/last.*
and RUN/best.* (lowest validation ADE).
"""

from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, Subset

from rasterize.frames import ego_from_world, ego_pose
from rasterize.raster import channels
from riskmap.data.dataset import DemoDataset, PerturbedEgo
from riskmap.infra.training_run import csv_log
from riskmap.planner.bc import CHECKPOINT_KIND, BCConfig, BCNet, bc_inputs
from riskmap.training.config import BaselineTrainConfig
from riskmap.training.train import (
    dataset_sidecar,
    raster_for,
    resolve_goal_variance,
    split_episodes,
    training_run,
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
    run = training_run(out, config, resume, CHECKPOINT_KIND)
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
    run.resume_from(model, optimizer)
    run.lock()   # one writer per run directory (creates it)
    data = dataset_sidecar(dataset, train_idx, val_idx)
    augment = (config.augment_probability, config.augment_heading_deg, config.augment_lateral_m)
    train_set = BCWindows(dataset, bc, augment, config.seed)
    val_loader = DataLoader(Subset(BCWindows(dataset, bc, None), val_idx), batch_size=config.batch_size)
    fields = ["epoch", "train_ade_m", "val_ade_m", "val_fde_m", "seconds"]

    def sidecar(epoch: int) -> dict:
        """The checkpoints' sidecar after `epoch`, the last committed one."""
        metrics = {k: v for k, v in run.log[-1].items() if k != "epoch"}
        return _sidecar(config, bc, dataset, data, metrics, epoch, run.best)

    run.publishes(log=csv_log(fields), sidecar=sidecar, kind=CHECKPOINT_KIND, last=True)
    run.republish(model)     # the run may have been killed between the commit and its files
    for epoch in range(run.first_epoch, config.epochs):
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
        run.commit(model, optimizer, {"epoch": epoch, **metrics})
        if progress:
            print(f"{config.kind} epoch {epoch + 1}/{config.epochs}: " +
                  ", ".join(f"{k} {v:.3f}" for k, v in metrics.items()), flush=True)
    return run.best
