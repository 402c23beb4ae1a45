"""The demonstration dataset: shards written by `riskmap collect`, served as training samples.

A sample (grid G = resolution, C = raster channels):
    raster       float32 [C, 200, 200]  BEV raster in [0, 1]; C = len(rasterize.raster.channels(
                                        dataset.raster_config)): 8, or 10 with predict_s > 0
    motion       float32 [3, G, G]      ego speed, cell x / length, cell y / width
    demo         float32 [2, G, G]      D_demo: path visit counts, goal one-hot
    uncertainty  float32 [G, G]         ado agents' positional uncertainty
    goal_map     float32 [G, G]         Gaussian around the goal cell
    goal_cell    int64   [2]            (row, col) of the goal: by default the route rule's
                                        (`rasterize.highway.RouteRule`, as in closed loop), or
                                        the demonstration's last in-grid cell (goal="demo")
    start_cell   int64   [2]            the ego's (row, col)
    demo_path    int64   [3G, 2]        the demonstration's cell path, padded with -1
    route_cells  int64   [256, 2]       cells of the route every metre from the ego, padded with -1
                                        (the risk-limited goal: `riskmap.planner.risk_goal`)
    future       float32 [F, 2]         the ego's future waypoints, ego frame, metres
With a space-time planner's settings (`spacetime`, T = its steps; DESIGN §3b) also:
    st_evidence    uint8→float32 [T, E, G, G]  per-step evidence the model sees, present only
                                               (`rasterize.spacetime.step_evidence`)
    st_uncertainty uint8→float32 [T, G, G]     N_t: the others' footprints at their recorded
                                               positions at step t (training signal only)
    st_demo        int64 [T, 2]                the human's cell at step t, −1 off the grid
"""

from __future__ import annotations

import json
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from rasterize.config import RasterConfig
from rasterize.errors import InputError
from rasterize.frames import ego_from_world, ego_pose
from rasterize.maps import (
    demo_path_cells,
    goal_map,
    motion_features,
    route_cells,
    route_goal_cell,
    start_cell,
    uncertainty_map,
    visitation_from_path,
)
from rasterize.raster import rasterize_scene
from rasterize.scene import Scene
from rasterize.scene_io import check_packed, unpack_scene
from riskmap.data.collect import FORMAT_VERSION, INDEX, MANIFEST
from riskmap.infra.atomic import read_npz

try:  # torch is optional for reading scenes, required for DataLoader use
    from torch.utils.data import Dataset as _TorchDataset
except ImportError:  # pragma: no cover
    _TorchDataset = object


def load_manifest(root: Path) -> dict:
    root = Path(root)
    path = root / MANIFEST
    if not path.exists():
        raise InputError(f"--data {root} is not a dataset (no {MANIFEST}); "
                         "create one with `riskmap collect`")
    try:
        return json.loads(path.read_text())
    except ValueError:
        raise InputError(f"{path} is not valid JSON; collect the dataset again") from None


def collected_raster_config(root: str | Path) -> RasterConfig:
    """The raster configuration a dataset was collected with (its manifest's)."""
    return RasterConfig.from_dict(load_manifest(Path(root))["config"]["raster"])


def _load_shard(path: Path) -> dict[str, np.ndarray]:
    if not path.exists():
        raise InputError(f"shard {path} listed in the index is missing; "
                         "run `riskmap collect ... --resume` to rebuild it")
    return read_npz(path, "shard", "delete it and run `riskmap collect ... --resume` to write it "
                    "again")


class DemoDataset(_TorchDataset):
    """Training windows of a collected dataset (see the module docstring for a sample's keys).

    `raster`: the raster configuration the caller needs (for instance a checkpoint's); it must
    equal the dataset's, since the extent was chosen with the scenario family at collection,
    except in `predict_s` and the pixel count: the predicted future is drawn from each window's
    present and the shards hold states, not pixels, so any horizon and any raster size can be
    drawn from any dataset. Samples are drawn with `raster` (else the dataset's).
    """

    def __init__(self, root: str | Path, resolution: int = 50, raster: RasterConfig | None = None,
                 sigma_x: float = 0.5, sigma_y: float = 1.5, goal_variance: float = 5.0,
                 goal: str = "route", spacetime=None):
        if goal not in ("route", "demo"):
            raise InputError(f"goal must be 'route' or 'demo', got {goal!r}")
        self.goal_source = goal
        self.root = Path(root)
        self.manifest = load_manifest(self.root)
        version = self.manifest.get("config", {}).get("format_version")
        if version != FORMAT_VERSION:
            raise InputError(f"dataset {self.root} has format version {version}, this toolkit reads "
                             f"version {FORMAT_VERSION}; collect it again with `riskmap collect`")
        collected = RasterConfig.from_dict(self.manifest["config"]["raster"])
        if raster is not None and replace(raster, predict_s=collected.predict_s, rows=collected.rows,
                                          cols=collected.cols) != collected:
            raise InputError(
                f"dataset {self.root} was collected with raster config {collected} but {raster} "
                "is required; collect a dataset with the matching extent or use a matching model"
            )
        self.raster_config = collected if raster is None else raster
        self.grid = collected.grid(resolution)
        self.sigma_x, self.sigma_y, self.goal_variance = sigma_x, sigma_y, goal_variance
        # riskmap.planner.st_model.SpaceTimeConfig, or None: the spatial planner's samples
        self.spacetime = spacetime
        self.source = self.manifest["config"]["env_id"]
        try:
            index = json.loads((self.root / INDEX).read_text())
        except (OSError, ValueError):
            raise InputError(f"{self.root / INDEX} is missing or unreadable; run "
                             "`riskmap collect ... --resume` to rebuild it") from None
        self.cache = None                           # see use_cache
        self.shard_paths: list[Path] = []           # per shard with windows: its file
        self._shards: list[dict[str, np.ndarray]] = []
        self._groups: list[str | None] = []        # per shard: its group, None without one
        self._items: list[tuple[int, int]] = []
        for entry in index["shards"]:
            if entry["windows"] == 0:
                continue
            path = self.root / entry["file"]
            arrays = _load_shard(path)
            count = check_packed(arrays, str(path))
            if count != entry["windows"]:
                raise InputError(f"shard {path} holds {count} windows but the index says "
                                 f"{entry['windows']}; run `riskmap collect ... --resume`")
            self._items.extend((len(self._shards), i) for i in range(count))
            self._shards.append(arrays)
            self.shard_paths.append(path)
            self._groups.append(entry.get("group"))
        if not self._items:
            raise InputError(f"dataset {self.root} holds no windows; collect more episodes")

    def __len__(self) -> int:
        return len(self._items)

    def episode_of(self, index: int) -> int:
        """The episode (shard) a window comes from."""
        return self._items[index][0]

    def group_of(self, index: int) -> str | None:
        """The group (recorded data: site and configuration) a window's episode belongs to, or
        None for data without groups (simulated episodes are independent)."""
        return self._groups[self._items[index][0]]

    @property
    def derived(self) -> dict:
        """Settings derived from recorded data at collection (`riskmap.data.collect_commonroad`):
        extent, route speed limit and acceleration, goal error; empty for simulated data."""
        return self.manifest.get("derived", {})

    def scene(self, index: int) -> Scene:
        shard, local = self._items[index]
        return unpack_scene(self._shards[shard], local, source=self.source)

    def __getitem__(self, index: int) -> dict:
        if self.cache is None:
            return self.sample(self.scene(index))
        arrays = self.cache.get(index)
        if arrays is None:
            arrays = self.sample_arrays(self.scene(index))
            try:
                self.cache.put(index, arrays)
            except OSError as err:              # the disk full: go on without the cache
                warnings.warn(f"sample cache given up: {err}", stacklevel=2)
                self.cache = None
        return as_tensors(arrays)

    def use_cache(self, cache) -> None:
        """Serve unperturbed windows from `cache` (`riskmap.data.sample_cache.SampleCache`, made
        for this dataset and its settings), building and storing those it lacks; None: none."""
        self.cache = cache

    def sample(self, scene: Scene) -> dict:
        """The training sample (see the module docstring) of a scene with a recorded future."""
        return as_tensors(self.sample_arrays(scene))

    def sample_arrays(self, scene: Scene) -> dict[str, np.ndarray]:
        """`sample`'s arrays before `as_tensors`: numpy, the raster still uint8 [C, 200, 200]."""
        origin, heading = ego_pose(scene)
        cells = demo_path_cells(scene, self.grid)
        counts, goal = visitation_from_path(cells, self.grid)
        path = np.full((3 * self.grid.rows, 2), -1, dtype=np.int64)
        cells = cells[: len(path)]
        path[: len(cells)] = cells
        if self.goal_source == "route":
            goal_cell = route_goal_cell(scene, self.grid)
        else:
            goal_cell = tuple(int(v) for v in np.argwhere(goal)[0])
        sample = {
            "raster": rasterize_scene(scene, self.raster_config),
            "motion": motion_features(scene, self.grid),
            "demo": np.stack([counts, goal]),
            "uncertainty": uncertainty_map(scene, self.grid, self.sigma_x, self.sigma_y),
            "goal_map": goal_map(goal_cell, self.grid, self.goal_variance),
            "goal_cell": np.array(goal_cell, dtype=np.int64),
            "start_cell": np.array(start_cell(self.grid), dtype=np.int64),
            "demo_path": path,
            "route_cells": route_cells(scene, self.grid),
            "future": ego_from_world(scene.ego_future_xy(), origin, heading).astype(np.float32),
        }
        if self.spacetime is not None:
            sample |= spacetime_arrays(scene, self.grid, self.spacetime, self.sigma_x, self.sigma_y)
        return sample


class PerturbedEgo(_TorchDataset):
    """Training-time augmentation: with probability `probability` the ego's current pose is turned
    by up to ±`max_heading_deg` and shifted up to ±`max_lateral_m` sideways (uniformly), its
    recorded future kept (see `Scene.with_ego_perturbed`). Draws depend only on (seed, epoch,
    index), so a resumed run sees the same samples."""

    def __init__(self, base: DemoDataset, seed: int = 0, probability: float = 0.5,
                 max_heading_deg: float = 10.0, max_lateral_m: float = 1.0):
        self.base, self.seed, self.probability = base, seed, probability
        self.max_heading = np.deg2rad(max_heading_deg)
        self.max_lateral = max_lateral_m
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.base)

    def perturbation(self, index: int) -> tuple[float, float] | None:
        """This epoch's draw for window `index`: (heading turn rad, lateral shift m), or None
        when the window is served as recorded."""
        rng = np.random.default_rng([self.seed, self.epoch, index])
        if rng.random() < self.probability:
            heading = rng.uniform(-self.max_heading, self.max_heading)
            return heading, rng.uniform(-self.max_lateral, self.max_lateral)
        return None

    def scene(self, index: int) -> Scene:
        """Window `index`'s scene, perturbed or not as this epoch's draw says."""
        scene = self.base.scene(index)
        draw = self.perturbation(index)
        return scene if draw is None else scene.with_ego_perturbed(*draw)

    def __getitem__(self, index: int) -> dict:
        draw = self.perturbation(index)
        if draw is None:
            return self.base[index]          # as recorded: the base's (cached) sample
        return self.base.sample(self.base.scene(index).with_ego_perturbed(*draw))


# Sample arrays stored as uint8 (255 = 1.0) to keep the sample cache small; `as_tensors` scales them.
UINT8_ARRAYS = ("raster", "st_evidence", "st_uncertainty")


def spacetime_arrays(scene: Scene, grid, spacetime, sigma_x: float, sigma_y: float
                     ) -> dict[str, np.ndarray]:
    """The space-time keys of a sample (module docstring) for settings `spacetime`."""
    from rasterize.spacetime import demo_cells_per_step, future_footprints, quantised, step_evidence

    steps, step_s = spacetime.steps, spacetime.step_s
    return {
        "st_evidence": quantised(step_evidence(scene, grid, steps, step_s, sigma_x, sigma_y)),
        "st_uncertainty": quantised(future_footprints(scene, grid, steps, step_s, sigma_x, sigma_y)),
        "st_demo": demo_cells_per_step(scene, grid, steps, step_s),
    }


def as_tensors(arrays: dict[str, np.ndarray]) -> dict:
    """A sample's tensors (the module docstring) from `DemoDataset.sample_arrays`: the uint8
    arrays (`UINT8_ARRAYS`) scaled to float32 [0, 1], every other array as it is."""
    import torch

    return {k: torch.from_numpy(v.astype(np.float32) / 255.0 if k in UINT8_ARRAYS else np.ascontiguousarray(v))
            for k, v in arrays.items()}


def with_human_goal(scene):
    """`scene` with its route replaced by the straight line to where the human was at the end of
    the recorded future, so the planner's goal is the human's (the `--goal human` protocol, as
    `riskmap.sim.worlds.commonroad_replay.CommonRoadWorld.scene` does in closed loop)."""
    import dataclasses

    end = scene.ego_future_xy()[-1]
    return dataclasses.replace(scene, route_xy=np.linspace(scene.ego_state()[:2], end, 200))
