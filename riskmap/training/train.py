"""`riskmap train`: MaxEnt IRL training of the risk-map generator on collected demonstrations.

Every epoch: a pass over the training episodes in a seeded order, then validation on held-out
episodes (demonstration NLL under the policy; ADE/FDE of the sampled plan against the recorded
future on a fixed subset). Writes RUN/state.pt (everything --resume needs, the epoch's one commit
point: `riskmap.infra.training_run`), then from it RUN/log.csv, RUN/last.* and RUN/best.* (lowest
validation ADE); TensorBoard scalars in RUN/tb/.

Windows served as recorded (validation, and training windows whose ego this epoch leaves
unperturbed) come from the sample cache (`riskmap.data.sample_cache`) once built; `workers`
DataLoader processes, where asked for, build samples while the network trains, in the same order
and with the same content as the training process would. On the CPU the network runs in the
channels-last memory layout (the same computation up to rounding, faster convolutions).
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import MISSING, asdict, fields, replace
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, Subset

from rasterize.config import RasterConfig
from rasterize.errors import InputError
from rasterize.raster import channels
from riskmap.data.dataset import DemoDataset, PerturbedEgo, collected_raster_config
from riskmap.data.groups import dataset_groups, match_groups, natural_key
from riskmap.data.sample_cache import open_sample_cache
from riskmap.infra.checkpoint import CHECKPOINT_KIND
from riskmap.infra.config_mapping import to_plain
from riskmap.infra.training_run import STATE, TrainingRun, csv_log, read_checkpoint_run
from riskmap.planner.irl import demo_negative_log_likelihood, irl_step
from riskmap.planner.model import (
    ModelConfig,
    RiskMapGenerator,
    demo_arc_lengths,
    load_backbone_weights,
    timing_loss,
    with_raster_channels,
)
from riskmap.planner.sampler import SamplerConfig, sample_trajectory
from riskmap.training.config import TrainConfig


def resolve_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise InputError(f"--device {name}: no CUDA device here; use --device cpu or auto")
    return torch.device(name)


def _held_out_groups(dataset: DemoDataset, groups: list[str], val_fraction: float,
                     val_groups: tuple[str, ...] | None) -> set[str]:
    """The groups to validate on: `val_groups` (`match_groups`), else the last
    ⌈val_fraction × groups⌉ in natural order."""
    if not val_groups:
        return set(groups[-max(1, math.ceil(val_fraction * len(groups))):])
    return match_groups(dataset, groups, val_groups)


def split_episodes(dataset: DemoDataset, val_fraction: float,
                   val_groups: tuple[str, ...] | None = None) -> tuple[list[int], list[int]]:
    """Window indices of training and validation windows.

    Recorded data (shards with a group): whole groups are held out, so a recorded moment of
    traffic never lands on both sides (`_held_out_groups`). Simulated data: the last episodes.
    """
    episodes = sorted({dataset.episode_of(i) for i in range(len(dataset))})
    groups = dataset_groups(dataset)
    if groups:
        if len(groups) < 2:
            raise InputError(f"dataset {dataset.root} holds one recorded group ({groups[0]}); "
                             "training needs at least 2 (one is held out for validation)")
        held = _held_out_groups(dataset, groups, val_fraction, val_groups)
        if held == set(groups):
            raise InputError(f"--val-groups holds out every group of {dataset.root}; leave some "
                             "to train on")
        is_val = [dataset.group_of(i) in held for i in range(len(dataset))]
    else:
        if val_groups:
            raise InputError(f"--val-groups: dataset {dataset.root} has no groups (only recorded "
                             "data from `riskmap collect --from-commonroad` has); drop the option")
        if len(episodes) < 2:
            raise InputError(f"dataset {dataset.root} has {len(episodes)} episode(s) with windows; "
                             "training needs at least 2 (one is held out for validation)")
        n_val = max(1, math.ceil(val_fraction * len(episodes)))
        val_eps = set(episodes[-n_val:])
        is_val = [dataset.episode_of(i) in val_eps for i in range(len(dataset))]
    train = [i for i in range(len(dataset)) if not is_val[i]]
    val = [i for i in range(len(dataset)) if is_val[i]]
    return train, val


DEFAULT_GOAL_VARIANCE = 5.0      # cells²; highway-env data (experiments/README.md)


def resolve_goal_variance(requested: float | None, dataset: DemoDataset) -> float:
    """The training goal variance (cells²): `requested`, else from the spread of the route
    rule's goal around where the humans were at the horizon's end (recorded data: the
    manifest's `derived.goal_error_rms_m`, metres along and across, over the grid's cells),
    else `DEFAULT_GOAL_VARIANCE`."""
    if requested is not None:
        return float(requested)
    rms = dataset.derived.get("goal_error_rms_m")
    if not rms:
        return DEFAULT_GOAL_VARIANCE
    grid = dataset.grid
    return round(0.5 * ((rms["along"] / grid.row_m) ** 2 + (rms["across"] / grid.col_m) ** 2), 3)


def _to(batch: dict, device: torch.device, channels_last: bool = False) -> dict:
    batch = {k: v.to(device) for k, v in batch.items()}
    if channels_last:
        batch["raster"] = batch["raster"].contiguous(memory_format=torch.channels_last)
    return batch


def use_channels_last(device: torch.device) -> bool:
    """Whether the network runs channels-last: on the CPU, where oneDNN's convolutions, batch norm
    and pooling are faster in that layout (forward and backward of a batch of 32 200x200 rasters
    on 2 cores: 0.85 s instead of 1.07 s; experiments/bench_train.py); elsewhere the layout is
    left as it is."""
    return device.type == "cpu"


def sample_workers(requested: int | None, device: torch.device) -> int:
    """How many processes build samples: `requested`, else none when the network trains on the
    CPU (its threads use every core, and a worker taking one stalls them all at their next
    barrier: slower on 2 cores, experiments/bench_train.py), else up to 4, a core left free."""
    if requested is not None:
        return requested
    return 0 if device.type == "cpu" else max(0, min(4, (os.cpu_count() or 1) - 1))


def _loader(dataset, batch_size: int, workers: int) -> DataLoader:
    """Batches in `dataset`'s order, built by `workers` processes (0: this one)."""
    return DataLoader(dataset, batch_size=batch_size, num_workers=workers,
                      prefetch_factor=2 if workers else None)


def attach_sample_cache(dataset: DemoDataset, config: TrainConfig, out: Path,
                        progress: bool = True) -> None:
    """Serve `dataset`'s unperturbed windows from its sample cache under `config.cache` (auto:
    DATA/cache, else OUT/cache where the dataset's folder cannot be written; off: none)."""
    if config.cache == "off":
        return
    roots = [Path(config.data) / "cache", out / "cache"] if config.cache == "auto" \
        else [Path(config.cache)]
    for root in roots:
        try:
            dataset.use_cache(open_sample_cache(dataset, root))
            return
        except OSError as err:
            error = f"{root}: {err.strerror or err}"
    if config.cache != "auto":
        raise InputError(f"--cache {config.cache}: cannot make the sample cache there ({error}); "
                         "pass a writable folder or --cache off")
    if progress:
        print(f"no sample cache ({error}); samples are built every epoch", file=sys.stderr)


def sampler_for(config: TrainConfig) -> SamplerConfig:
    """The sampler a run's checkpoint plans with: today's default, timed by the timing head
    where the run trains one."""
    return SamplerConfig(timing="learned") if config.timing_head else SamplerConfig()


def _forward(model, batch: dict, timed: bool) -> tuple[torch.Tensor, torch.Tensor | None]:
    """(risk [B, G, G], the timing head's arc lengths [B, 12] m or None)."""
    if timed:
        return model.forward_timed(batch["raster"], batch["motion"])
    return model(batch["raster"], batch["motion"]), None


def _evaluate(model, loader, config: TrainConfig, irl, grid, device,
              channels_last: bool = False) -> dict:
    model.eval()
    nll, ade, fde, timing, seen = [], [], [], [], 0
    sampler = sampler_for(config)
    with torch.no_grad():
        for batch in loader:
            batch = _to(batch, device, channels_last)
            risk, arcs = _forward(model, batch, config.timing_head)
            step = irl_step(risk, batch, irl)
            nll.append(demo_negative_log_likelihood(step.policy, batch["demo_path"]).cpu())
            if arcs is not None:
                timing.append((arcs - demo_arc_lengths(batch["future"])).abs().mean(dim=1).cpu())
            for i in range(risk.shape[0]):
                if seen >= config.val_ade_windows:
                    break
                plan = sample_trajectory(step.policy[i].cpu(), tuple(batch["start_cell"][i].tolist()),
                                         config.horizon, grid, sampler, seed=seen,
                                         speed_mps=float(batch["motion"][i, 0, 0, 0]),
                                         arc_lengths=None if arcs is None else arcs[i].double().cpu().numpy())
                err = np.linalg.norm(plan - batch["future"][i].cpu().numpy(), axis=1)
                ade.append(err.mean())
                fde.append(err[-1])
                seen += 1
    metrics = {"val_nll": float(torch.cat(nll).mean()), "val_ade_m": float(np.mean(ade)),
               "val_fde_m": float(np.mean(fde))}
    if timing:      # mean |arc length error| over the 12 waypoints, metres
        metrics["val_timing_m"] = float(torch.cat(timing).mean())
    return metrics


def dataset_sidecar(dataset: DemoDataset, train_idx: list[int], val_idx: list[int]) -> dict:
    """What a checkpoint records of its data: source, window counts, held-out groups and the
    settings derived from recorded data (the route rule's speed limit and acceleration, which
    the planner needs in closed loop: `riskmap.sim.worlds.commonroad_replay.route_scene_config`)."""
    groups = sorted({dataset.group_of(i) for i in val_idx} - {None}, key=natural_key)
    return {"env_id": dataset.source, "windows": len(dataset), "train_windows": len(train_idx),
            "val_windows": len(val_idx), "val_groups": groups, "derived": dataset.derived,
            "git_commit": dataset.manifest.get("git_commit")}


def _sidecar(config: TrainConfig, model_config: ModelConfig, dataset: DemoDataset, irl,
             data: dict, metrics: dict, epoch: int) -> dict:
    return {
        "model": model_config.to_dict(),
        "raster": dataset.raster_config.to_dict(),
        "grid": dataset.grid.to_dict(),
        "irl": asdict(irl),
        "train": asdict(config),
        "sampler": asdict(sampler_for(config)),
        "maps": {"sigma_x": config.sigma_x, "sigma_y": config.sigma_y,
                 "goal_variance": irl.goal_variance, "goal": config.goal},
        "dataset": data,
        "epoch": epoch,
        "metrics": metrics,
    }


def raster_for(data: str, predict_s: float | None, raster_px: int | None = None) -> RasterConfig | None:
    """The raster a run draws: the dataset's, with `predict_s` seconds of predicted future and
    `raster_px` x `raster_px` pixels over the same extent when given (None for both: the
    dataset's own, unchanged). The shards hold states, not pixels, so any size can be drawn."""
    if predict_s is None and raster_px is None:
        return None
    raster = collected_raster_config(data)
    if predict_s is not None:
        raster = replace(raster, predict_s=predict_s)
    if raster_px is not None:
        raster = replace(raster, rows=raster_px, cols=raster_px)
    return raster


# Settings a resume may change: how long to train, and how samples are made (not what they are).
RESUMABLE_CHANGES = ("epochs", "workers", "cache")


def same_settings(saved: dict, config) -> bool:
    """Whether a run's saved `train` settings are `config`'s but for `RESUMABLE_CHANGES`. A
    setting newer than the saved run (absent from its sidecar) counts as at its default, so that
    runs begun before it existed still resume."""
    defaults = {f.name: f.default for f in fields(config) if f.default is not MISSING}
    current = to_plain(config)
    free = {name: current[name] for name in RESUMABLE_CHANGES if name in current}
    return defaults | saved | free == current


def training_run(out: Path, config, resume: bool, kind: str) -> TrainingRun:
    """The run of `riskmap train` or `train-baseline` in `out` (`riskmap.infra.training_run`),
    refused without `resume` when the folder holds one (its state, or the last checkpoint of a
    run begun before state.pt, which it then resumes from): best by validation ADE, resumed only
    with `config`'s settings but for `RESUMABLE_CHANGES`."""
    run = TrainingRun(out, resume, metric="val_ade_m", best={"val_ade_m": math.inf},
                      settings=to_plain(config), same=lambda saved: same_settings(saved, config),
                      fix="resume with the same flags (only --epochs may change) or choose another --out",
                      older=lambda: read_checkpoint_run(out, kind))
    return run.refuse(markers=(STATE, "last.json"))


def _init_from(model: RiskMapGenerator, model_config: ModelConfig, checkpoint: Path) -> None:
    """Start from a trained risk-map checkpoint's weights (fine-tuning); its network must be the
    one this run builds (grid resolution, raster channels), except that a raster with more
    channels (`--predict-s` on a checkpoint trained without) starts with the added ones off
    (`with_raster_channels`), and a timing head the checkpoint lacks (`--timing-head`) starts
    fresh."""
    from riskmap.planner.model import load_model

    trained, side = load_model(checkpoint)
    old = ModelConfig(**side["model"])
    adds_head = model_config.timing_head and not old.timing_head
    grows = old.in_channels < model_config.in_channels
    # Only more raster channels and a new head may differ; never fewer, never a head dropped.
    same_network = replace(old, in_channels=model_config.in_channels,
                           timing_head=model_config.timing_head) == model_config
    shrinks = old.in_channels > model_config.in_channels or (old.timing_head and not model_config.timing_head)
    if not same_network or shrinks:
        raise InputError(f"--init-checkpoint {checkpoint} is a {side['model']} network, this run "
                         f"builds {model_config.to_dict()}; use a matching --resolution, --predict-s "
                         "and --timing-head")
    state = trained.state_dict()
    if grows:
        state = with_raster_channels(state, model_config.in_channels)
    if adds_head:
        state |= {k: v for k, v in model.state_dict().items() if k.startswith("timing.")}
    model.load_state_dict(state)


def train(config: TrainConfig, resume: bool = False, progress: bool = True, on_epoch=None,
          channels_last: bool | None = None) -> dict:
    """Train; returns the best epoch's metrics.

    `on_epoch(epoch, record)`, when given, gets each epoch's per-batch training losses and
    timings: {"losses", "nlls", "train_windows", "val_windows", "train_s" (the pass over the
    training windows), "data_s" (of which waiting for batches), "val_s" (validation)}.
    `channels_last`: the network's memory layout (None: `use_channels_last`)."""
    from torch.utils.tensorboard import SummaryWriter
    from tqdm import tqdm

    out = Path(config.out)
    run = training_run(out, config, resume, CHECKPOINT_KIND)
    device = resolve_device(config.device)
    torch.manual_seed(config.seed)
    dataset = DemoDataset(config.data, config.resolution,
                          raster=raster_for(config.data, config.predict_s, config.raster_px),
                          sigma_x=config.sigma_x, sigma_y=config.sigma_y, goal=config.goal)
    dataset.goal_variance = resolve_goal_variance(config.goal_variance, dataset)
    irl = config.irl(dataset.goal_variance)
    train_idx, val_idx = split_episodes(dataset, config.val_fraction, config.val_groups)
    if config.max_windows:
        train_idx = train_idx[: config.max_windows]
        val_idx = val_idx[: max(1, config.max_windows // 4)]
    augmented = PerturbedEgo(dataset, config.seed, config.augment_probability,
                             config.augment_heading_deg, config.augment_lateral_m)
    model_config = ModelConfig(in_channels=len(channels(dataset.raster_config)),
                               resolution=config.resolution, timing_head=config.timing_head)
    spacetime = config.planner == "spacetime"
    if spacetime:
        from riskmap.training import spacetime as st_train

        st, reach = st_train.spacetime_config(config, dataset, train_idx)
        dataset.spacetime = st
        irl = st_train.irl_config(config, st, dataset.goal_variance)
        model = st_train.build_model(model_config, st, config.init_checkpoint)
        if progress:
            print(f"space-time planner: T={st.steps} steps of {st.step_s:g} s, K={st.max_forward} "
                  f"cells forward, L={st.max_across} across per step", file=sys.stderr)
    else:
        model = RiskMapGenerator(model_config)
    if config.backbone_weights:
        load_backbone_weights(model, config.backbone_weights)
    if config.init_checkpoint and not spacetime:
        _init_from(model, model_config, Path(config.init_checkpoint))
    model.to(device)
    if channels_last is None:
        channels_last = use_channels_last(device)
    if channels_last:
        model.to(memory_format=torch.channels_last)
    trained_parameters = model.timing.parameters() if config.freeze_risk else model.parameters()
    optimizer = torch.optim.Adam(trained_parameters, lr=config.lr)
    run.resume_from(model, optimizer)
    run.lock()   # one writer per run directory (creates it)
    attach_sample_cache(dataset, config, out, progress)
    data = dataset_sidecar(dataset, train_idx, val_idx)
    writer = SummaryWriter(str(out / "tb"), purge_step=run.first_epoch)
    workers = sample_workers(config.workers, device)
    val_loader = _loader(Subset(dataset, val_idx), config.batch_size, workers)
    fields = ["epoch", "train_loss", "train_nll", "val_nll", "val_ade_m", "val_fde_m", "seconds"]
    if config.timing_head:
        fields[3:3] = ["train_timing"]
        fields[-1:-1] = ["val_timing_m"]

    def sidecar(epoch: int) -> dict:
        """The checkpoints' sidecar after `epoch`, the last committed one."""
        metrics = {k: v for k, v in run.log[-1].items() if k != "epoch"}
        side = _sidecar(config, model_config, dataset, irl, data, metrics, epoch) | {"best": run.best}
        if spacetime:
            side |= st_train.sidecar_extra(st, reach)
        return side

    run.publishes(log=csv_log(fields), sidecar=sidecar, kind=CHECKPOINT_KIND, last=True)
    run.republish(model)     # the run may have been killed between the commit and its files
    for epoch in range(run.first_epoch, config.epochs):
        started = time.perf_counter()
        model.train()
        if config.freeze_risk:          # the risk network's batch norms keep their statistics
            model.eval()
            model.timing.train()
        order = torch.randperm(len(train_idx),
                               generator=torch.Generator().manual_seed(config.seed * 100003 + epoch))
        augmented.set_epoch(epoch)
        loader = _loader(Subset(augmented, [train_idx[i] for i in order]), config.batch_size,
                         workers)
        losses, nlls, timings, waited = [], [], [], 0.0
        bar = tqdm(loader, desc=f"epoch {epoch + 1}/{config.epochs}", disable=not progress,
                   leave=False)
        batches = iter(bar)
        while True:
            asked = time.perf_counter()
            batch = next(batches, None)
            waited += time.perf_counter() - asked
            if batch is None:
                break
            batch = _to(batch, device, channels_last)
            if spacetime:
                loss, nll = st_train.train_step(model, batch, irl)
                irl_loss = loss
            else:
                risk, arcs = _forward(model, batch, config.timing_head)
                step = irl_step(risk, batch, irl)
                loss = irl_loss = step.loss
                if arcs is not None:
                    timed = timing_loss(arcs, batch["future"])
                    timings.append(timed.item())
                    loss = timed if config.freeze_risk else loss + timed
                nll = demo_negative_log_likelihood(step.policy, batch["demo_path"]).mean().item()
            optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), config.grad_clip)
            optimizer.step()
            losses.append(irl_loss.item())
            nlls.append(nll)
            bar.set_postfix(nll=f"{np.mean(nlls):.2f}")
        trained = time.perf_counter()
        metrics = {"train_loss": float(np.mean(losses)), "train_nll": float(np.mean(nlls)),
                   **({"train_timing": float(np.mean(timings))} if timings else {}),
                   **(st_train.evaluate(model, val_loader, config, irl, dataset.grid, device,
                                        lambda b: _to(b, device, channels_last)) if spacetime else
                      _evaluate(model, val_loader, config, irl, dataset.grid, device, channels_last))}
        if on_epoch is not None:
            on_epoch(epoch, {"losses": losses, "nlls": nlls, "train_windows": len(train_idx),
                             "val_windows": len(val_idx), "train_s": trained - started,
                             "data_s": waited, "val_s": time.perf_counter() - trained})
        metrics["seconds"] = round(time.perf_counter() - started, 1)
        for key, value in metrics.items():
            writer.add_scalar(key, value, epoch)
        writer.flush()   # on disk before the commit: a resumed run purges only later epochs
        run.commit(model, optimizer, {"epoch": epoch, **metrics})
        if progress:
            print(f"epoch {epoch + 1}/{config.epochs}: " +
                  ", ".join(f"{k} {v:.3f}" for k, v in metrics.items()), flush=True)
    writer.close()
    return run.best
