"""The space-time planner: BEV raster and per-step evidence → reward maps r_1 … r_T → value
iteration in space-time → time-indexed policy → sampled positions at each step (DESIGN §3b).

It decides where *and when*: standing still and slowing are actions, and a cell another agent
is predicted to take at step t can be cheap before and after t and costly at t. The goal map is
learned from the route rule's (the network's input; `riskmap.planner.st_model`); the plan's
`goal_map` is exp(g), in (0, 1].
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np
import torch

from rasterize.config import GridConfig, RasterConfig
from rasterize.errors import InputError
from rasterize.frames import ego_from_world, ego_pose
from rasterize.maps import goal_map, motion_features, route_goal_cell, start_cell, uncertainty_map
from rasterize.raster import rasterize_scene
from rasterize.scene import Scene
from rasterize.spacetime import predicted_footprints, quantised, step_evidence
from riskmap.infra.checkpoint import require_sections, route_settings_of
from riskmap.planner.irl import goal_log_map
from riskmap.planner.st_model import SpaceTimeConfig, load_spacetime_model
from riskmap.planner.st_sampler import SpaceTimeSamplerConfig, spacetime_plan
from riskmap.planner.st_vi import spacetime_value_iteration, spacetime_visitation
from riskmap.sim.loop.plan import Plan

# What planning reads from a space-time checkpoint's sidecar besides the network's own sections
# (`load_spacetime_model` checks those): section -> the keys it cannot do without.
PLANNING_SECTIONS = {"grid": (), "irl": ("goal_variance",), "maps": ("sigma_x", "sigma_y")}


@dataclass(frozen=True)
class TimeGapConfig:
    """A planning-time price on following too closely, from the per-step evidence alone: the
    cells another agent is predicted to cover within the `time_gap_s` seconds up to step t (its
    footprints at steps t − k … t, k = time_gap_s / step; step 0 is now) cost `weight` × that
    footprint at step t. Being where a car was 1 s earlier is a 1 s time gap, so this keeps a
    headway behind a leader and a margin behind a car clearing a crossing. `ahead_only` prices
    only the agents whose centre is ahead of the ego's now (ego-frame x ≥ 0): a follower's
    predicted footprints cover the ego's own cells, and pricing them pushes a waiting ego forward.
    Off (weight 0) unless a checkpoint's sidecar `planning.time_gap` names it (measured in
    experiments/README.md)."""

    time_gap_s: float = 1.0
    weight: float = 0.0
    ahead_only: bool = False

    def __post_init__(self) -> None:
        if not (0.0 <= self.time_gap_s <= 6.0 and 0.0 <= self.weight < float("inf")):
            raise InputError(f"planning time_gap {self}: time_gap_s must be 0 … 6 s and weight "
                             ">= 0; fix the sidecar's planning.time_gap")
        if not isinstance(self.ahead_only, bool):
            raise InputError(f"planning time_gap ahead_only {self.ahead_only!r} must be true or false; "
                             "fix the sidecar's planning.time_gap")

    def penalty(self, now: np.ndarray, predicted: np.ndarray, step_s: float) -> np.ndarray:
        """[T, G, G] to subtract from r_1 … r_T: `now` [G, G] and `predicted` [T, G, G] in [0, 1]."""
        seq = np.concatenate([now[None], predicted])                  # steps 0 … T
        k = int(round(self.time_gap_s / step_s))
        shadow = np.stack([seq[max(0, t - k): t + 1].max(axis=0) for t in range(1, len(seq))])
        return self.weight * shadow


@dataclass(frozen=True)
class ReachConfig:
    """A planning-time bound on how far along x the ego can be at step t from its speed now v0:
    cells whose forward offset from the ego's cell lies outside [lo_t − tol, hi_t + tol] cost
    `weight` at step t, where hi_t = v0 t + ½ accel t² and lo_t = v0 t − ½ decel t² (v0²/2 decel
    once stopped), t in seconds, tol = `tolerance_cells` × the row length. The space-time actions
    move 0 … max_forward cells per step whatever the speed, so without it a plan may put the ego
    several cells ahead of where its speed can take it within 0.5 s (an implausible first step)
    and its timing is the map's, not the car's. Off (weight 0) unless a checkpoint's sidecar
    `planning.reach` names it (measured in experiments/README.md)."""

    accel_mps2: float = 2.0
    decel_mps2: float = 6.0
    tolerance_cells: float = 1.0
    weight: float = 0.0

    def __post_init__(self) -> None:
        if not (0.0 < self.accel_mps2 <= 20.0 and 0.0 < self.decel_mps2 <= 20.0
                and 0.0 <= self.tolerance_cells <= 10.0 and 0.0 <= self.weight < float("inf")):
            raise InputError(f"planning reach {self}: accel_mps2 and decel_mps2 must be in (0, 20] "
                             "m/s², tolerance_cells in [0, 10] and weight >= 0; fix the sidecar's "
                             "planning.reach")

    def penalty(self, speed_mps: float, grid: GridConfig, steps: int, step_s: float) -> np.ndarray:
        """[T, G, G] to subtract from r_1 … r_T."""
        from rasterize.frames import cell_centres_ego

        x = cell_centres_ego(grid)[..., 0]                        # [G, G] metres ahead of the ego
        x = x - x[start_cell(grid)]
        t = step_s * np.arange(1, steps + 1)[:, None, None]
        v0 = max(float(speed_mps), 0.0)
        hi = v0 * t + 0.5 * self.accel_mps2 * t ** 2
        lo = np.where(t < v0 / self.decel_mps2, v0 * t - 0.5 * self.decel_mps2 * t ** 2,
                      v0 ** 2 / (2.0 * self.decel_mps2))
        tol = self.tolerance_cells * grid.extent.length_m / grid.rows
        outside = (x[None] > hi + tol) | (x[None] < lo - tol)
        return self.weight * outside.astype(np.float32)


def planning_setting(side: dict, name: str, config_type: type):
    """`config_type` from the sidecar's `planning.<name>` (its defaults, off, where absent); a
    section that is not a mapping of the config's fields is refused in one line."""
    settings = side.get("planning", {}).get(name)
    if settings is None:
        return config_type()
    known = [f.name for f in fields(config_type)]
    if not isinstance(settings, dict) or set(settings) - set(known):
        raise InputError(f"the sidecar's planning.{name} {settings!r} is not a mapping of "
                         f"{', '.join(known)}; fix or remove it")
    return config_type(**settings)


def without_agents_behind(scene: Scene) -> Scene:
    """`scene` with the other agents whose centre is behind the ego's now (ego-frame x < 0)
    marked absent at every step."""
    origin, heading = ego_pose(scene)
    x = ego_from_world(scene.states[:, scene.current_index, :2], origin, heading)[:, 0]
    keep = x >= 0.0
    keep[scene.ego_index] = True
    return replace(scene, valid=scene.valid & keep[:, None])


class SpaceTimePlanner:
    """`reset(scene)`, `plan(scene) -> Plan`; the plan's `risk_map` is r_1 (the map in force
    now), `risk_steps` all T maps, `svf_steps` the visitation per step (computed when read)."""

    def __init__(self, model: torch.nn.Module, raster: RasterConfig, grid: GridConfig,
                 spacetime: SpaceTimeConfig, goal_variance: float, sigma_x: float = 0.5,
                 sigma_y: float = 1.5, sampler: SpaceTimeSamplerConfig = SpaceTimeSamplerConfig(),
                 seed: int = 0):
        from riskmap.planner.model import for_inference

        self.model, self.raster, self.grid = for_inference(model), raster, grid
        self.spacetime, self.goal_variance = spacetime, goal_variance
        self.sigma_x, self.sigma_y = sigma_x, sigma_y
        self.sampler, self.seed = sampler, seed
        self.route_settings: dict | None = None   # route rule of recorded training data, if any
        self.time_gap = TimeGapConfig()            # off; see TimeGapConfig
        self.reach = ReachConfig()                 # off; see ReachConfig
        # Planning-time pull towards the route rule's goal added to the learned goal map:
        # g + route_goal_weight · (−d² / 2σ²), d in cells from the route goal, σ² the goal
        # variance (0: the learned goal alone). The sidecar's `planning.route_goal_weight`.
        self.route_goal_weight = 0.0
        self._calls = 0

    @classmethod
    def load(cls, checkpoint: str | Path, seed: int = 0,
             goal_variance: float | None = None) -> SpaceTimePlanner:
        """Goal variance (cells²): `goal_variance`, else the sidecar's `planning.goal_variance`,
        else the training value.

        A `goal_variance` given here (`--goal-variance` of drive and evaluate) asks to plan
        towards the goal the scene's route gives (with `evaluate --goal human`, where the human
        is 6 s ahead) at that variance, as the spatial planner does: it switches the pull towards
        the route goal on at weight 1 where the sidecar leaves it off, since without the pull
        the learned goal map ignores the variance and the option would do nothing."""
        model, side = load_spacetime_model(Path(checkpoint))
        require_sections(side, checkpoint, PLANNING_SECTIONS)
        variance = goal_variance
        if variance is None:
            variance = side.get("planning", {}).get("goal_variance", side["irl"]["goal_variance"])
        if not variance > 0:
            raise InputError(f"goal variance must be > 0 cells², got {variance}")
        planner = cls(model, RasterConfig.from_dict(side["raster"]), GridConfig.from_dict(side["grid"]),
                      SpaceTimeConfig(**side["spacetime"]), variance, side["maps"]["sigma_x"],
                      side["maps"]["sigma_y"], SpaceTimeSamplerConfig(**side.get("sampler", {})),
                      seed)
        planner.route_settings = route_settings_of(side)
        weight = side.get("planning", {}).get("route_goal_weight", 0.0)
        if not (isinstance(weight, (int, float)) and 0.0 <= weight < float("inf")):
            raise InputError(f"the sidecar's planning.route_goal_weight {weight!r} must be a number "
                             ">= 0; fix or remove it")
        planner.route_goal_weight = float(weight)
        if goal_variance is not None and planner.route_goal_weight == 0.0:
            planner.route_goal_weight = 1.0
        planner.time_gap = planning_setting(side, "time_gap", TimeGapConfig)
        planner.reach = planning_setting(side, "reach", ReachConfig)
        return planner

    def reset(self, scene: Scene) -> None:
        self._calls = 0

    def plan(self, scene: Scene) -> Plan:
        scene = scene.past()
        st, t = self.spacetime, {}
        t0 = time.perf_counter()
        raster = rasterize_scene(scene, self.raster)
        motion = motion_features(scene, self.grid)
        evidence = quantised(step_evidence(scene, self.grid, st.steps, st.step_s, self.sigma_x,
                                           self.sigma_y)).astype(np.float32) / 255.0
        goal_cell, start = route_goal_cell(scene, self.grid), start_cell(self.grid)
        route = goal_map(goal_cell, self.grid, self.goal_variance)
        t["raster"] = time.perf_counter() - t0
        with torch.inference_mode():
            t0 = time.perf_counter()
            # The raster straight into the channels-last layout the network runs fastest on.
            image = torch.empty((1, *raster.shape), memory_format=torch.channels_last)
            image[0].copy_(torch.from_numpy(raster)).div_(255.0)
            reward, g = self.model.planning_maps(image, torch.from_numpy(motion)[None],
                                                 torch.from_numpy(evidence)[None],
                                                 torch.from_numpy(route)[None])
            t["network"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            if self.route_goal_weight > 0:
                g = g + self.route_goal_weight * goal_log_map(
                    torch.tensor([goal_cell]), self.grid.rows, self.grid.cols, self.goal_variance)
            if self.time_gap.weight > 0:
                priced, predicted = scene, evidence[:, 0]
                if self.time_gap.ahead_only:
                    priced = without_agents_behind(scene)
                    footprints = predicted_footprints(priced, self.grid, st.steps, st.step_s,
                                                      self.sigma_x, self.sigma_y)
                    predicted = quantised(footprints).astype(np.float32) / 255.0
                now = quantised(uncertainty_map(priced, self.grid, self.sigma_x, self.sigma_y))
                penalty = self.time_gap.penalty(now.astype(np.float32) / 255.0, predicted, st.step_s)
                reward = reward - torch.from_numpy(penalty)[None]
            if self.reach.weight > 0:
                penalty = self.reach.penalty(scene.ego_state()[4], self.grid, st.steps, st.step_s)
                reward = reward - torch.from_numpy(penalty)[None]
            _, policy = spacetime_value_iteration(reward, g, st.max_forward, st.max_across)
            t["vi"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        waypoints, _ = spacetime_plan(policy[0], start, self.grid, st.max_forward, st.max_across,
                                      self.sampler, seed=(self.seed * 1_000_003 + self._calls) % 2**32)
        t["sampler"] = time.perf_counter() - t0
        self._calls += 1
        t["total"] = sum(t.values())

        plan = Plan(waypoints, reward[0, 0].numpy(), np.exp(g[0].numpy()), None, None, goal_cell, t,
                    risk_steps=reward[0].numpy())

        def visits() -> np.ndarray:     # figures and open-loop metrics only
            return spacetime_visitation(policy, torch.tensor([start]), st.max_forward,
                                        st.max_across)[0].numpy()

        plan.svf_steps = visits
        plan.svf = lambda: plan.svf_steps.sum(axis=0)
        return plan
