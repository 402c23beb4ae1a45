"""The risk-map planner: BEV raster → risk map → soft value iteration → SVF → sampled plan."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from rasterize.config import GridConfig, RasterConfig
from rasterize.errors import InputError
from rasterize.maps import (
    goal_map,
    motion_features,
    route_cells,
    route_goal_cell,
    route_goal_point,
    start_cell,
)
from rasterize.raster import rasterize_scene
from rasterize.scene import Scene
from riskmap.infra.checkpoint import require_sections, route_settings_of
from riskmap.planner.gap_keeping import keep_gap
from riskmap.planner.irl import goal_log_map
from riskmap.planner.risk_goal import RiskGoalConfig, risk_goal_cell
from riskmap.planner.sampler import SamplerConfig, sample_trajectory
from riskmap.planner.vi import soft_value_iteration, state_visitation
from riskmap.sim.loop.plan import Plan

# What planning reads from a spatial checkpoint's sidecar besides the network's own sections
# (`load_model` checks those): section -> the keys it cannot do without.
PLANNING_SECTIONS = {"grid": (), "irl": ("goal_variance", "horizon", "gamma"), "sampler": ()}


def sampler_of(side: dict) -> SamplerConfig:
    """A checkpoint's sampler: as trained (older sidecars' defaults are filled in by
    `riskmap.infra.checkpoint.SIDECAR_FORMAT`), with a planning-time `timing`, `keep_gap` or
    `gap_prediction` from the sidecar's `planning` section over it."""
    settings = dict(side["sampler"])
    for key in ("timing", "keep_gap", "gap_prediction"):
        if key in side.get("planning", {}):
            settings[key] = side["planning"][key]
    return SamplerConfig(**settings)


def risk_goal_of(side: dict) -> RiskGoalConfig | None:
    """The checkpoint's risk-limited goal (`riskmap.planner.risk_goal`): the sidecar's
    `planning.risk_goal` settings, else its training's `irl.risk_goal`; None (the route rule's
    goal alone, as every checkpoint before it) where neither names one."""
    settings = side.get("planning", {}).get("risk_goal", side.get("irl", {}).get("risk_goal"))
    if settings is None:
        return None
    known = set(RiskGoalConfig.__dataclass_fields__)
    if not isinstance(settings, dict) or set(settings) - known:
        raise InputError(f"the sidecar's risk_goal {settings!r} is not a mapping of "
                         f"{', '.join(sorted(known))}; fix or remove it")
    return RiskGoalConfig(**settings)


def load_planner(checkpoint: str | Path, seed: int = 0, goal_variance: float | None = None):
    """The planner of a risk-map checkpoint, whichever kind its sidecar names: the spatial
    `RiskMapPlanner` (the paper's), or the space-time `SpaceTimePlanner` (`planner: spacetime`)."""
    from riskmap.infra.checkpoint import read_sidecar
    from riskmap.planner.st_model import is_spacetime

    if is_spacetime(read_sidecar(Path(checkpoint))):
        from riskmap.planner.st_planner import SpaceTimePlanner

        return SpaceTimePlanner.load(checkpoint, seed=seed, goal_variance=goal_variance)
    return RiskMapPlanner.load(checkpoint, seed=seed, goal_variance=goal_variance)


class RiskMapPlanner:
    """BEV raster → risk map → soft value iteration → SVF → sampled 12-waypoint trajectory.

    The goal is the route rule's (`rasterize.highway.RouteRule`): the last point of the ego's
    route ahead inside the grid, the same rule that built the training goal maps; with
    `risk_goal` set, held short of the first point of the route the risk map blocks
    (`riskmap.planner.risk_goal`).
    """

    def __init__(self, model: torch.nn.Module, raster: RasterConfig, grid: GridConfig,
                 horizon: int, goal_variance: float, gamma: float = 1.0,
                 sampler: SamplerConfig = SamplerConfig(), seed: int = 0):
        from riskmap.planner.model import for_inference

        # The network as planning runs it (batch norms folded, channels-last): `for_inference`.
        self.model, self.raster, self.grid = for_inference(model), raster, grid
        self.horizon, self.goal_variance, self.gamma = horizon, goal_variance, gamma
        self.sampler, self.seed = sampler, seed
        self.route_settings: dict | None = None   # route rule of recorded training data, if any
        self.risk_goal: RiskGoalConfig | None = None  # see risk_goal_of
        self._calls = 0

    @classmethod
    def load(cls, checkpoint: str | Path, seed: int = 0,
             goal_variance: float | None = None) -> RiskMapPlanner:
        """Planning-time goal variance (cells²), first found of: `goal_variance`, the sidecar's
        `planning.goal_variance`, the training value `irl.goal_variance`.

        Why it may differ from training: the goal enters value iteration as −d²/(2σ²) against
        per-cell rewards of about −1 to −2 on lanes, so the policy stops where one more cell
        towards the goal gains less than a cell costs, (2d − 1)/(2σ²) < |r|. With σ² = 5 that is
        ~8 cells (~38 m on highway) short of the goal, and a short plan means a slow ego. A
        narrower goal at planning time moves the end onto the goal without retraining
        (experiments/README.md, "Planning-time goal variance").
        """
        from riskmap.planner.model import load_model

        model, side = load_model(Path(checkpoint))
        require_sections(side, checkpoint, PLANNING_SECTIONS)
        variance = goal_variance
        if variance is None:
            variance = side.get("planning", {}).get("goal_variance", side["irl"]["goal_variance"])
        if variance <= 0:
            raise InputError(f"goal variance must be > 0 cells², got {variance}")
        sampler = sampler_of(side)
        if sampler.timing == "learned" and model.timing is None:
            raise InputError(f"checkpoint {checkpoint} plans with learned timing but its network "
                             "has no timing head; set the sidecar's planning timing to kinematic")
        planner = cls(model, RasterConfig.from_dict(side["raster"]), GridConfig.from_dict(side["grid"]),
                      side["irl"]["horizon"], variance, side["irl"]["gamma"], sampler, seed)
        planner.route_settings = route_settings_of(side)
        planner.risk_goal = risk_goal_of(side)
        return planner

    def reset(self, scene: Scene) -> None:
        self._calls = 0

    def plan(self, scene: Scene) -> Plan:
        scene = scene.past()
        t = {}
        t0 = time.perf_counter()
        raster = rasterize_scene(scene, self.raster)
        motion = motion_features(scene, self.grid)
        goal_cell = route_goal_cell(scene, self.grid)
        start = start_cell(self.grid)
        t["raster"] = time.perf_counter() - t0
        with torch.inference_mode():
            t0 = time.perf_counter()
            image = torch.from_numpy(raster).float().div_(255.0)[None]
            image = image.contiguous(memory_format=torch.channels_last)
            motion_t = torch.from_numpy(motion)[None]
            arc_lengths = None
            if self.sampler.timing == "learned":
                risk, arcs = self.model.forward_timed(image, motion_t)
                arc_lengths = arcs[0].double().numpy()
            else:
                risk = self.model(image, motion_t)
            t["network"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            goal_xy, variance = route_goal_point(scene, self.grid), self.goal_variance
            if self.risk_goal is not None:
                limited = risk_goal_cell(risk[0].numpy(), route_cells(scene, self.grid),
                                         float(scene.ego_state()[4]), self.risk_goal)
                if limited is not None:        # the path ends at the held-back cell's centre
                    goal_cell, goal_xy, variance = limited, None, self.risk_goal.goal_variance
            g = goal_log_map(torch.tensor([goal_cell]), self.grid.rows, self.grid.cols, variance)
            _, policy = soft_value_iteration(risk, g, self.horizon, self.gamma)
            t["vi"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        waypoints = sample_trajectory(policy[0], start, self.horizon, self.grid, self.sampler,
                                      seed=(self.seed * 1_000_003 + self._calls) % 2**32,  # any planner seed
                                      speed_mps=float(scene.states[scene.ego_index, scene.current_index, 4]),
                                      goal_xy=goal_xy, arc_lengths=arc_lengths)
        if self.sampler.keep_gap:
            waypoints = keep_gap(waypoints, scene, self.sampler.dt_s,
                                 prediction=self.sampler.gap_prediction)
        t["sampler"] = time.perf_counter() - t0
        self._calls += 1
        t["total"] = sum(t.values())
        horizon = self.horizon

        def svf() -> np.ndarray:          # only figures and open-loop metrics read it
            return state_visitation(policy, torch.tensor([start]), horizon)[0][0].numpy()

        return Plan(waypoints, risk[0].numpy(), goal_map(goal_cell, self.grid, variance),
                    policy[0].numpy(), svf, goal_cell, t)
