"""Space-time plan figures: the r_t / D_t strip, and `plan_figures` writing it only for
space-time plans. Synthetic plans only: no network, no training."""

from __future__ import annotations

import numpy as np
import pytest

from rasterize.config import Extent, GridConfig, RasterConfig
from rasterize.frames import ego_from_grid, grid_from_ego
from riskmap.figures import panels
from riskmap.figures.panels import has_spacetime, save_spacetime_strip
from riskmap.sim.loop.plan import Plan
from tests.scenes import constant_velocity_scene

G, T = 20, 12
EXTENT = Extent(front_m=60.0, back_m=20.0, left_m=40.0, right_m=40.0)
GRID = GridConfig(EXTENT, G, G)
RASTER = RasterConfig(EXTENT, 40, 40, history_s=1.0)


def spacetime_plan(grid: GridConfig = GRID, steps: int = T, speed: float = 5.0) -> Plan:
    """Ego driving straight ahead at `speed`; an obstacle (a low-reward blob) that comes towards
    it down the rows, drifting right; D_t one-hot on the ego's cell at step t."""
    times = np.arange(1, steps + 1) * 6.0 / steps
    waypoints = np.stack([speed * np.arange(1, 13) * 0.5, np.zeros(12)], axis=1)
    rows, cols = np.meshgrid(np.arange(grid.rows), np.arange(grid.cols), indexing="ij")
    risk = np.empty((steps, grid.rows, grid.cols))
    visits = np.zeros((steps, grid.rows, grid.cols))
    for k, t_s in enumerate(times):
        centre_row = 1 + k * (grid.rows - 6) / (steps - 1)
        centre_col = grid.cols / 2 - 4 + 0.4 * k
        blob = np.exp(-((rows - centre_row) ** 2 + (cols - centre_col) ** 2) / 3.0)
        risk[k] = -0.05 - 0.02 * np.abs(cols - grid.cols / 2 + 0.5) - 4.0 * blob
        row, col = grid_from_ego(np.array([speed * t_s, 0.0]), grid)
        visits[k, row, col] = 1.0
    plan = Plan(waypoints, risk[0], np.zeros((grid.rows, grid.cols)), None, None,
                (0, grid.cols // 2), {"total": 0.01}, risk_steps=risk)
    plan.svf_steps = lambda: visits
    plan.svf = lambda: plan.svf_steps.sum(axis=0)
    return plan


def spatial_plan(grid: GridConfig = GRID) -> Plan:
    plan = spacetime_plan(grid)
    return Plan(plan.waypoints, plan.risk_map, plan.goal_map, np.zeros((5, grid.rows, grid.cols)),
                np.full((grid.rows, grid.cols), 0.1), plan.goal_cell, {"total": 0.01})


def test_synthetic_plan_is_consistent():
    plan = spacetime_plan()
    assert plan.risk_steps.shape == (T, G, G) and (plan.risk_steps <= 0).all()
    # D_t's cell is the plan's waypoint at t (T = 12: step t is waypoint t - 1).
    cells = np.argwhere(plan.svf_steps.reshape(T, -1) == 1.0)[:, 1]
    centres = ego_from_grid(np.stack(np.unravel_index(cells, (G, G)), axis=1), GRID)
    assert np.abs(centres - plan.waypoints).max() <= max(GRID.row_m, GRID.col_m)


def test_has_spacetime():
    assert has_spacetime(spacetime_plan())
    assert not has_spacetime(spatial_plan())


@pytest.mark.parametrize("every, columns", [(None, 6), (1, 12), (3, 4)])
def test_strip_writes_a_readable_png(tmp_path, every, columns):
    import matplotlib.image

    plan = spacetime_plan()
    demo = plan.waypoints + [[0.5 * i, 1.0] for i in range(12)]
    path = save_spacetime_strip(plan, GRID, tmp_path / "sub" / "strip.png", "synthetic",
                                demo_xy=demo, every=every)
    assert path == tmp_path / "sub" / "strip.png" and path.stat().st_size > 10_000
    image = matplotlib.image.imread(path)
    height, width = image.shape[:2]
    assert 600 <= height <= 1200                      # two rows of panels at 100 dpi
    assert 200 * columns <= width <= 300 * columns + 200
    assert image[..., :3].std() > 0.05                # not a blank picture


def test_strip_without_demonstration_or_visits(tmp_path):
    plan = spacetime_plan()
    plan.svf_steps = None
    path = save_spacetime_strip(plan, GRID, tmp_path / "strip.png")
    assert path.stat().st_size > 0


def test_strip_rejects_a_bad_stride(tmp_path):
    with pytest.raises(ValueError):
        save_spacetime_strip(spacetime_plan(), GRID, tmp_path / "strip.png", every=0)


class _FakeDataset:
    source = "synthetic"

    def __init__(self, data, rows, raster=None):
        pass

    def __len__(self) -> int:
        return 1

    def scene(self, index: int):
        return constant_velocity_scene(n_past=2, n_future=12, ego_speed=5.0)

    def group_of(self, index: int):
        return None


class _FakePlanner:
    raster, grid = RASTER, GRID

    def __init__(self, make_plan):
        self.make_plan = make_plan

    def plan(self, scene):
        return self.make_plan()


@pytest.mark.parametrize("make_plan, strip", [(spatial_plan, False), (spacetime_plan, True)])
def test_plan_figures_writes_the_strip_for_spacetime_plans_only(tmp_path, monkeypatch,
                                                                make_plan, strip):
    import riskmap.data.dataset
    import riskmap.planner.riskmap_planner

    monkeypatch.setattr(riskmap.data.dataset, "DemoDataset", _FakeDataset)
    monkeypatch.setattr(riskmap.planner.riskmap_planner, "load_planner",
                        lambda checkpoint, seed=0, goal_variance=None: _FakePlanner(make_plan))
    paths = panels.plan_figures(tmp_path / "ckpt", tmp_path / "data", tmp_path / "out", count=1)
    names = sorted(p.name for p in paths)
    assert names == (["plan_00000.png", "plan_00000_steps.png"] if strip else ["plan_00000.png"])
    assert all(p.exists() and p.stat().st_size > 0 for p in paths)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == names
