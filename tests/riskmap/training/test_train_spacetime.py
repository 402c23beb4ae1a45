"""`riskmap train --planner spacetime`: a tiny run, its checkpoint, resume, and the kinds kept apart."""

import json

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from rasterize.errors import InputError
from riskmap.data.dataset import DemoDataset
from riskmap.planner.model import load_model
from riskmap.planner.riskmap_planner import RiskMapPlanner, load_planner
from riskmap.planner.st_model import load_spacetime_model
from riskmap.planner.st_planner import SpaceTimePlanner
from riskmap.registry import make_planner
from riskmap.training.train import train
from tests.riskmap.conftest import tiny_train_config

ST = dict(planner="spacetime", steps=6, max_forward=3, max_across=2)


@pytest.fixture(scope="module")
def st_checkpoint(tiny_dataset, tiny_checkpoint, tmp_path_factory):
    """Fine-tuned from the tiny spatial checkpoint, as the shipped ones are."""
    out = tmp_path_factory.mktemp("st") / "run"
    train(tiny_train_config(tiny_dataset, out, epochs=1, init_checkpoint=str(tiny_checkpoint), **ST),
          progress=False)
    return out / "best"


def test_a_spacetime_run_writes_a_checkpoint_that_plans(st_checkpoint, tiny_dataset):
    side = json.loads(st_checkpoint.with_suffix(".json").read_text())
    assert side["planner"] == "spacetime"
    assert side["spacetime"] == {"steps": 6, "max_forward": 3, "max_across": 2}
    assert np.isfinite(side["metrics"]["val_nll"]) and np.isfinite(side["metrics"]["val_ade_m"])
    planner = make_planner(f"riskmap:{st_checkpoint}", seed=2)
    assert isinstance(planner, SpaceTimePlanner)
    scene = DemoDataset(tiny_dataset).scene(0)
    plan = planner.plan(scene)
    again = load_planner(st_checkpoint, seed=2).plan(scene)
    np.testing.assert_array_equal(plan.waypoints, again.waypoints)
    assert plan.waypoints.shape == (12, 2) and np.isfinite(plan.waypoints).all()
    assert plan.risk_steps.shape == (6, 25, 25) and (plan.risk_steps <= 0).all()
    np.testing.assert_array_equal(plan.risk_map, plan.risk_steps[0])
    np.testing.assert_allclose(plan.svf_steps.sum(axis=(1, 2)), 1.0, rtol=1e-5)
    np.testing.assert_allclose(plan.svf, plan.svf_steps.sum(axis=0), rtol=1e-6)
    assert set(plan.timings_s) >= {"raster", "network", "vi", "sampler", "total", "svf"}


def test_the_two_kinds_are_not_mistaken_for_each_other(st_checkpoint, tiny_checkpoint):
    with pytest.raises(InputError, match="space-time planner; this needs a spatial"):
        load_model(st_checkpoint)
    with pytest.raises(InputError, match="spatial risk-map planner; this needs a space-time"):
        load_spacetime_model(tiny_checkpoint)
    assert isinstance(load_planner(tiny_checkpoint), RiskMapPlanner)


def test_a_spacetime_run_resumes_exactly(tiny_dataset, tmp_path):
    full, cut = tmp_path / "full", tmp_path / "cut"
    settings = dict(max_windows=4, val_ade_windows=1, **ST)
    train(tiny_train_config(tiny_dataset, full, epochs=2, **settings), progress=False)
    train(tiny_train_config(tiny_dataset, cut, epochs=1, **settings), progress=False)
    train(tiny_train_config(tiny_dataset, cut, epochs=2, **settings), resume=True, progress=False)
    a, b = load_file(str(full / "last.safetensors")), load_file(str(cut / "last.safetensors"))
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=0)


def test_the_reach_comes_from_the_data_when_not_given(tiny_dataset, tmp_path):
    train(tiny_train_config(tiny_dataset, tmp_path / "r", epochs=1, max_windows=4,
                            val_ade_windows=1, planner="spacetime"), progress=False)
    side = json.loads((tmp_path / "r" / "last.json").read_text())
    reach = side["spacetime_reach"]
    assert side["spacetime"]["max_forward"] >= 1 and reach["windows"] > 0
    assert side["spacetime"]["max_forward"] <= max(1, reach["forward_max"])


@pytest.mark.parametrize("clash", [dict(timing_head=True), dict(goal="demo"),
                                   dict(risk_goal_threshold=-3.0)])
def test_spatial_only_settings_are_refused(tiny_dataset, tmp_path, clash):
    with pytest.raises(InputError, match="--planner spacetime"):
        tiny_train_config(tiny_dataset, tmp_path / "x", planner="spacetime", **clash)


def test_planning_settings_come_from_the_sidecar_and_bad_ones_are_named(st_checkpoint, tmp_path):
    import shutil

    side = json.loads(st_checkpoint.with_suffix(".json").read_text())
    copy = tmp_path / "ck"
    shutil.copy(st_checkpoint.with_suffix(".safetensors"), copy.with_suffix(".safetensors"))
    side["planning"] = {"route_goal_weight": 0.5, "time_gap": {"time_gap_s": 1.0, "weight": 20.0},
                        "reach": {"accel_mps2": 3.0, "weight": 50.0}}
    copy.with_suffix(".json").write_text(json.dumps(side))
    planner = load_planner(copy)
    assert planner.route_goal_weight == 0.5 and planner.time_gap.weight == 20.0
    assert planner.reach.weight == 50.0 and planner.reach.accel_mps2 == 3.0 and planner.reach.decel_mps2 == 6.0
    assert load_planner(copy, goal_variance=0.25).route_goal_weight == 0.5   # the sidecar's kept


def test_a_time_gap_for_agents_ahead_only_prices_no_follower(st_checkpoint, tiny_dataset, tmp_path):
    """`planning.time_gap.ahead_only`: the time gap is computed from the agents ahead of the ego
    alone, so the plan differs from pricing every agent exactly when an agent is behind."""
    import shutil

    from rasterize.frames import ego_from_world, ego_pose
    from rasterize.maps import uncertainty_map
    from rasterize.spacetime import predicted_footprints
    from riskmap.planner.st_planner import without_agents_behind

    side = json.loads(st_checkpoint.with_suffix(".json").read_text())
    plans = {}
    for ahead_only in (False, True):
        copy = tmp_path / f"ck_{ahead_only}"
        shutil.copy(st_checkpoint.with_suffix(".safetensors"), copy.with_suffix(".safetensors"))
        side["planning"] = {"time_gap": {"time_gap_s": 1.0, "weight": 1000.0, "ahead_only": ahead_only}}
        copy.with_suffix(".json").write_text(json.dumps(side))
        planner = load_planner(copy, seed=1)
        assert planner.time_gap.ahead_only is ahead_only
        plans[ahead_only] = [planner.plan(DemoDataset(tiny_dataset).scene(i)) for i in range(4)]
    seen_behind = 0
    for i in range(4):
        scene = DemoDataset(tiny_dataset).scene(i).past()
        kept = without_agents_behind(scene)
        assert kept.valid[scene.ego_index].any()
        now = scene.current_index
        x = [ego_from_world(scene.states[a, now, :2], *ego_pose(scene))[0]
             for a in np.flatnonzero(scene.valid[:, now] & ~kept.valid[:, now])]
        assert all(v < 0 for v in x)
        maps = [(uncertainty_map(s, planner.grid), predicted_footprints(s, planner.grid, 12, 0.5))
                for s in (scene, kept)]
        priced_differently = any(not np.array_equal(a, b) for a, b in zip(*maps))
        seen_behind += priced_differently
        same = np.array_equal(plans[False][i].risk_steps, plans[True][i].risk_steps)
        assert same != priced_differently, f"scene {i}: a follower on the grid {priced_differently}"
    assert seen_behind > 0


def test_a_given_goal_variance_plans_towards_the_given_goal(st_checkpoint, tiny_dataset):
    """--goal-variance (as with evaluate --goal human): the pull towards the scene's goal is on,
    so the plan's terminal visitation sits nearer that goal than without it."""
    free, given = load_planner(st_checkpoint, seed=1), load_planner(st_checkpoint, seed=1, goal_variance=0.25)
    assert free.route_goal_weight == 0.0 and given.route_goal_weight == 1.0 and given.goal_variance == 0.25
    scene = DemoDataset(tiny_dataset).scene(0)
    distance = []
    for planner in (free, given):
        plan = planner.plan(scene)
        rows, cols = np.indices(plan.svf_steps.shape[1:])
        last = plan.svf_steps[-1] / plan.svf_steps[-1].sum()
        distance.append(float((last * np.hypot(rows - plan.goal_cell[0], cols - plan.goal_cell[1])).sum()))
    assert distance[1] < distance[0]


def test_bad_planning_settings_are_named(st_checkpoint, tmp_path):
    import shutil

    side = json.loads(st_checkpoint.with_suffix(".json").read_text())
    copy = tmp_path / "ck"
    shutil.copy(st_checkpoint.with_suffix(".safetensors"), copy.with_suffix(".safetensors"))
    for bad in ({"route_goal_weight": -1}, {"time_gap": {"gap": 1}}, {"reach": {"speed": 1}},
                {"reach": {"accel_mps2": 0.0, "weight": 1.0}}, {"time_gap": {"ahead_only": "yes"}}):
        side["planning"] = bad
        copy.with_suffix(".json").write_text(json.dumps(side))
        with pytest.raises(InputError, match="planning"):
            load_planner(copy)


def test_a_coarser_raster_is_drawn_from_the_same_dataset_and_planned_with(tiny_dataset,
                                                                          tiny_checkpoint, tmp_path):
    """--raster-px: the shards hold states, so the run draws 50 x 50 pixels over the collected
    extent; the sidecar keeps the size and the planner draws what the network was trained on."""
    train(tiny_train_config(tiny_dataset, tmp_path / "px", epochs=1, raster_px=50,
                            init_checkpoint=str(tiny_checkpoint), **ST), progress=False)
    side = json.loads((tmp_path / "px" / "best.json").read_text())
    collected = DemoDataset(tiny_dataset).raster_config
    assert (side["raster"]["rows"], side["raster"]["cols"]) == (50, 50) != (collected.rows, collected.cols)
    assert side["raster"]["extent"] == collected.to_dict()["extent"]
    planner = load_planner(tmp_path / "px" / "best", seed=0)
    assert planner.raster.rows == 50
    plan = planner.plan(DemoDataset(tiny_dataset).scene(0))
    assert plan.waypoints.shape == (12, 2) and np.isfinite(plan.waypoints).all()


@pytest.mark.parametrize("pixels", [8, 401])
def test_a_raster_size_out_of_range_is_refused(tiny_dataset, tmp_path, pixels):
    with pytest.raises(InputError, match="--raster-px must be 16 to 400"):
        tiny_train_config(tiny_dataset, tmp_path / "x", raster_px=pixels)
