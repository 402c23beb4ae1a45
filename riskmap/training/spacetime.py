"""The space-time planner's parts of `riskmap train --planner spacetime` (DESIGN §3b): its reach
from the data, its network, its IRL step and its validation."""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from rasterize.errors import InputError
from rasterize.maps import start_cell
from rasterize.spacetime import demo_cells_per_step
from riskmap.planner.model import ModelConfig, with_raster_channels
from riskmap.planner.st_irl import SpaceTimeIRLConfig, demo_step_nll, st_irl_step
from riskmap.planner.st_model import (
    MAX_ACROSS_CELLS,
    MAX_FORWARD_CELLS,
    PLANNER_KIND,
    SpaceTimeConfig,
    SpaceTimeRiskMapGenerator,
    is_spacetime,
    state_from_spatial,
)
from riskmap.planner.st_sampler import SpaceTimeSamplerConfig, spacetime_plan

# The reach from the data covers this share of the demonstrations' steps (the rest, jumps of
# noisy recordings and the odd sprint, are not worth a larger action set in every plan).
REACH_QUANTILE = 0.995
REACH_WINDOWS = 400              # windows, evenly spread over the training set, read for it


def reach_from_data(dataset, indices: list[int], steps: int, step_s: float
                    ) -> tuple[int, int, dict]:
    """(K, L, what was measured): the cells per step forward and across that cover
    `REACH_QUANTILE` of the human's steps between consecutive on-grid cells."""
    picks = [indices[k] for k in np.unique(np.linspace(0, len(indices) - 1,
                                                       min(REACH_WINDOWS, len(indices))).astype(int))]
    forward, across = [], []
    for i in picks:
        scene = dataset.scene(int(i))
        cells = np.concatenate([[start_cell(dataset.grid)],
                                demo_cells_per_step(scene, dataset.grid, steps, step_s)])
        both = (cells[1:, 0] >= 0) & (cells[:-1, 0] >= 0)
        delta = (cells[1:] - cells[:-1])[both]
        forward.extend(-delta[:, 0])
        across.extend(np.abs(delta[:, 1]))
    if not forward:
        raise InputError(f"dataset {dataset.root}: no demonstration stays on the grid for two "
                         "steps; collect with a larger extent")
    k = int(np.clip(math.ceil(np.quantile(forward, REACH_QUANTILE)), 1, MAX_FORWARD_CELLS))
    lat = int(np.clip(math.ceil(np.quantile(across, REACH_QUANTILE)), 1, MAX_ACROSS_CELLS))
    return k, lat, {"windows": len(picks), "quantile": REACH_QUANTILE,
                    "forward_max": int(np.max(forward)), "across_max": int(np.max(across))}


def spacetime_config(config, dataset, train_idx: list[int]) -> tuple[SpaceTimeConfig, dict]:
    """The run's space-time settings: its flags, the reach the data needs where not given."""
    steps = config.steps
    measured = {}
    k, lat = config.max_forward, config.max_across
    if k is None or lat is None:
        step_s = SpaceTimeConfig(steps).step_s
        k_data, l_data, measured = reach_from_data(dataset, train_idx, steps, step_s)
        k = k_data if k is None else k
        lat = l_data if lat is None else lat
    return SpaceTimeConfig(steps, k, lat), measured


def build_model(model_config: ModelConfig, st: SpaceTimeConfig, init_checkpoint: str | None
                ) -> SpaceTimeRiskMapGenerator:
    """The network, started from `init_checkpoint` where given: a spatial checkpoint lends its
    encoder and head (`state_from_spatial`), a space-time one everything (same settings)."""
    model = SpaceTimeRiskMapGenerator(model_config, st)
    if not init_checkpoint:
        return model
    from riskmap.infra.checkpoint import load_tensors, read_sidecar

    path = Path(init_checkpoint)
    side = read_sidecar(path)
    state = load_tensors(path)
    old = ModelConfig(**side["model"])
    if old.resolution != model_config.resolution or old.in_channels > model_config.in_channels:
        raise InputError(f"--init-checkpoint {path} is a {side['model']} network, this run builds "
                         f"{model_config.to_dict()}; use a matching --resolution and --predict-s")
    if old.in_channels < model_config.in_channels:
        state = with_raster_channels(state, model_config.in_channels)
    if is_spacetime(side):
        if SpaceTimeConfig(**side["spacetime"]).steps != st.steps:
            raise InputError(f"--init-checkpoint {path} has {side['spacetime']['steps']} steps, this "
                             f"run {st.steps}; pass --steps {side['spacetime']['steps']}")
        model.load_state_dict(state)
    else:
        model.load_state_dict(state_from_spatial(model, state))
    return model


def forward(model, batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """(rewards [B, T, G, G], goal map [B, G, G]) of a batch."""
    return model(batch["raster"], batch["motion"], batch["st_evidence"], batch["goal_map"])


def irl_config(config, st: SpaceTimeConfig, goal_variance: float) -> SpaceTimeIRLConfig:
    return SpaceTimeIRLConfig(st, config.uncertainty_weight, goal_variance)


def train_step(model, batch: dict, irl: SpaceTimeIRLConfig) -> tuple[torch.Tensor, float]:
    """(loss to descend, the batch's mean demonstration NLL per step)."""
    step = st_irl_step(*forward(model, batch), batch, irl)
    return step.loss, float(demo_step_nll(step.visitation, batch["st_demo"]).mean())


def evaluate(model, loader, config, irl: SpaceTimeIRLConfig, grid, device, to) -> dict:
    """val_nll (mean −log D_t at the human's cell), and ADE/FDE of the plan on the first
    `config.val_ade_windows` windows."""
    model.eval()
    st = irl.spacetime
    nll, ade, fde, seen = [], [], [], 0
    sampler = SpaceTimeSamplerConfig()
    with torch.no_grad():
        for batch in loader:
            batch = to(batch)
            step = st_irl_step(*forward(model, batch), batch, irl)
            nll.append(demo_step_nll(step.visitation, batch["st_demo"]).cpu())
            for i in range(step.policy.shape[0]):
                if seen >= config.val_ade_windows:
                    break
                plan, _ = spacetime_plan(step.policy[i].cpu(), tuple(batch["start_cell"][i].tolist()),
                                         grid, st.max_forward, st.max_across, sampler, seed=seen)
                err = np.linalg.norm(plan - batch["future"][i].cpu().numpy(), axis=1)
                ade.append(err.mean())
                fde.append(err[-1])
                seen += 1
    return {"val_nll": float(torch.cat(nll).mean()), "val_ade_m": float(np.mean(ade)),
            "val_fde_m": float(np.mean(fde))}


def sidecar_extra(st: SpaceTimeConfig, measured: dict) -> dict:
    """What a space-time checkpoint's sidecar adds (and overrides) to the spatial one's."""
    return {"planner": PLANNER_KIND, "spacetime": st.to_dict(), "spacetime_reach": measured,
            "sampler": asdict(SpaceTimeSamplerConfig())}
