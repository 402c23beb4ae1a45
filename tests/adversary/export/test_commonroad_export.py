"""`adversary export --format commonroad`: attacked scenes written as CommonRoad scenarios and read
back with commonroad-io (its XML reader: `CommonRoadFileReader` also imports a protobuf reader that
the installed protobuf runtime cannot load, see `rasterize.commonroad.load_scenario`)."""

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from adversary.cli import main
from adversary.crash.attack import AttackConfig
from adversary.crash.judge import braking_track, first_collision, judge, rollout, splice_tracks
from adversary.crash.recorded import recording_traffic
from adversary.crash.run import run_attacks
from adversary.crash.scene_sweep import RecordingSweep, record_scenes
from adversary.crash.scenes import AttackScene, load_record, record_attack_scene
from adversary.export.commonroad import OBSTACLE_ID_OFFSET, write_commonroad
from rasterize.commonroad_compat import XMLFileReader, XMLFileWriter, region_contains
from rasterize.tracks import Tracks
from riskmap.registry import cached_planner
from tests.adversary.conftest import exit_code

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"
RECORDING = FIXTURES / "USA_US101-4_1_T-1.xml"     # as tests/adversary/crash/test_recorded_scenes.py
TRAFFIC = "checkpoints/crash_traffic_us101"


@pytest.fixture(scope="module")
def attack_run(tmp_path_factory) -> Path:
    """A one-scene CRASH run on the fixture recording: the first usable vehicle (obstacle 400) as
    the ego, driven by the recordings' IDM/MOBIL, attacked by its nearest neighbour."""
    base = tmp_path_factory.mktemp("export")
    record_scenes(RecordingSweep((str(RECORDING),)), 1, base / "scenes", progress=False)
    config = AttackConfig(selector="nearest", iterations_closed_loop=10, replan_every=10)
    run_attacks("idm", base / "scenes", 1, config, 0, base / "attack", TRAFFIC, None, progress=False)
    return base / "attack"


@pytest.fixture(scope="module")
def exported(attack_run) -> Path:
    out = attack_run.parent / "exported"
    assert main(["export", "--run", str(attack_run), "--format", "commonroad", "--out", str(out),
                 "--quiet"]) == 0
    return out


def _only_attack(run: Path) -> tuple[str, dict]:
    [path] = (run / "attacks").glob("*.json")
    return path.stem, json.loads(path.read_text())


def _driven(attack: dict, record):
    """The attacked run rebuilt here, independently of the exporter: the spliced log and the ego's
    drive on the log's steps (first valid step on), and the attack's log step t0."""
    log = splice_tracks(record, np.array(attack["tracks"]), attack["metrics"]["spliced_rows"])
    ego_states = np.array(attack["ego_states"])
    first = int(np.argmax(log.valid[log.ego_id]))
    return log, ego_states, first, record.t0_step


def _trajectory(obstacle, steps):
    """[T, 2] positions, [T] orientations, [T] speeds of a read-back obstacle (NaN where absent)."""
    out = np.full((len(steps), 4), np.nan)
    for i, k in enumerate(steps):
        s = obstacle.state_at_time(int(k))
        if s is not None:
            out[i] = [*s.position, s.orientation, s.velocity]
    return out[:, :2], out[:, 2], out[:, 3]


def _first_collision(ego: np.ndarray, ego_size, other: np.ndarray, other_size) -> int | None:
    """The judge's own collision test (`adversary.crash.judge.first_collision`) on the read-back
    ego and adversary (states [T, 6]; a row is valid where it is finite): its first step."""
    states = np.stack([ego, other])
    valid = np.isfinite(states).all(axis=2)
    sizes = np.array([ego_size, other_size], float)
    tracks = Tracks(np.nan_to_num(states), valid, sizes, np.zeros(2, np.int8))
    step, _, _ = first_collision(tracks, 0, [1])
    return step


def _states(xy, theta, speed):
    return np.column_stack([xy, np.cos(theta), np.sin(theta), speed, np.zeros(len(speed))])


def test_exported_scene_reads_back_with_the_run_s_vehicles_and_ego(attack_run, exported):
    name, attack = _only_attack(attack_run)
    assert attack["status"] == "ok" and attack["collision"], attack.get("metrics")    # the attack won
    record = load_record(Path(json.loads((attack_run / "run.json").read_text())["scenes"]) / f"{name}.npz")
    xml = exported / f"{name}.xml"
    assert XMLFileWriter.check_validity_of_commonroad_file(xml.read_bytes())     # CommonRoad's own XSD
    scenario, problems = XMLFileReader(str(xml)).open()
    sidecar = json.loads((exported / f"{name}.json").read_text())
    log, ego_states, first, k0 = _driven(attack, record)
    last = first + len(ego_states) - 1
    ids = recording_traffic(RECORDING).ids
    original, _ = XMLFileReader(str(RECORDING)).open()

    # the recording's road, and every other vehicle on the road for 2+ steps from t0, by its own id
    assert {la.lanelet_id for la in scenario.lanelet_network.lanelets} == \
        {la.lanelet_id for la in original.lanelet_network.lanelets}
    expected = {int(ids[a]) for a in range(len(ids))
                if a != log.ego_id and log.valid[a, k0:last + 1].sum() >= 2}
    assert {o.obstacle_id for o in scenario.dynamic_obstacles} == expected
    assert len(scenario.dynamic_obstacles) == len(expected) >= 2
    assert expected <= {o.obstacle_id for o in original.dynamic_obstacles}
    assert scenario.dt == pytest.approx(0.1) and sidecar["time_step_0"]["log_step"] == k0

    # the adversary: the record's generated trajectory, at every 0.1 s step within 1e-6 m
    adversary = int(record.agent_ids[attack["adversary_row"]])
    assert sidecar["adversary"]["obstacle_id"] == int(ids[adversary])
    obstacle = scenario.obstacle_by_id(int(ids[adversary]))
    steps = np.arange(0, last - k0 + 1)
    xy, theta, speed = _trajectory(obstacle, steps)
    assert np.abs(xy - log.states[adversary, k0:last + 1, :2]).max() < 1e-6
    assert np.abs(speed - log.states[adversary, k0:last + 1, 4]).max() < 1e-6
    row = attack["metrics"]["spliced_rows"].index(attack["adversary_row"])
    knots = np.array(attack["tracks"])[row]                           # the record's 2 Hz track
    at = np.arange(1, len(knots) + 1) * record.stride
    assert np.abs(xy[at] - knots[:, :2]).max() < 1e-6
    assert np.abs(np.angle(np.exp(1j * (theta[at] - np.arctan2(knots[:, 3], knots[:, 2]))))).max() < 1e-6
    # a vehicle no one generated replays its recording
    replayed = next(a for a in range(len(ids)) if int(ids[a]) in expected
                    and int(ids[a]) not in sidecar["spliced_obstacle_ids"])
    xy, _, _ = _trajectory(scenario.obstacle_by_id(int(ids[replayed])), steps)
    present = np.isfinite(xy[:, 0])
    assert np.abs(xy[present] - log.states[replayed, k0:last + 1, :2][present]).max() < 1e-6

    # the ego: the planning problem, starting where the ego was at t0
    [problem] = problems.planning_problem_dict.values()
    assert problem.planning_problem_id == record.scene.ego_id == sidecar["planning_problem_id"]
    assert record.scene.ego_id not in {o.obstacle_id for o in scenario.dynamic_obstacles}
    start = ego_states[k0 - first]
    assert problem.initial_state.time_step == 0
    assert np.abs(np.asarray(problem.initial_state.position) - start[:2]).max() < 1e-6
    assert problem.initial_state.velocity == pytest.approx(start[4], abs=1e-6)
    assert problem.initial_state.orientation == pytest.approx(np.arctan2(start[3], start[2]), abs=1e-6)
    [goal] = problem.goal.state_list
    assert goal.time_step.start == 0 and goal.time_step.end == sidecar["horizon_steps"] == 60
    assert region_contains(goal.position, sidecar["goal"]["center"])
    # the ego's drive from t0 is in the sidecar, at the same steps
    driven = np.array(sidecar["ego"]["trajectory"])
    assert np.array_equal(driven[:, 0], steps)
    assert np.abs(driven[:, 1:3] - ego_states[k0 - first:, :2]).max() < 1e-6


def test_collision_step_survives_the_round_trip(attack_run, exported):
    """Box overlap of the exported ego and adversary: the first collision is the record's."""
    name, attack = _only_attack(attack_run)
    scenario, _ = XMLFileReader(str(exported / f"{name}.xml")).open()
    sidecar = json.loads((exported / f"{name}.json").read_text())
    driven = np.array(sidecar["ego"]["trajectory"])
    steps = driven[:, 0].astype(int)
    ego = _states(driven[:, 1:3], driven[:, 3], driven[:, 4])
    adversary = scenario.obstacle_by_id(sidecar["adversary"]["obstacle_id"])
    other = _states(*_trajectory(adversary, steps))
    size = (sidecar["ego"]["length_m"], sidecar["ego"]["width_m"])
    other_size = (adversary.obstacle_shape.length, adversary.obstacle_shape.width)
    step = _first_collision(ego, size, other, other_size)
    k0 = sidecar["time_step_0"]["log_step"]
    assert step is not None and steps[step] == round(attack["metrics"]["collision_time_s"] / 0.1) - k0
    assert sidecar["collision"]["time_step"] == sidecar["collision"]["recomputed_time_step"] == steps[step]


def test_only_failures_plot_resume_and_bad_input(attack_run, exported, tmp_path, capsys):
    name, _ = _only_attack(attack_run)
    out = tmp_path / "failures"
    args = ["export", "--run", str(attack_run), "--format", "commonroad", "--out", str(out), "--quiet"]
    assert main([*args, "--only-failures", "--plot"]) == 0
    index = json.loads((out / "index.json").read_text())
    assert [e["scene"] for e in index["exported"]] == [name] and index["skipped"] == []
    assert (out / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    before = (out / f"{name}.xml").stat().st_mtime_ns
    assert main([*args, "--only-failures", "--plot", "--resume"]) == 0          # nothing redone
    assert (out / f"{name}.xml").stat().st_mtime_ns == before
    capsys.readouterr()

    scenes = json.loads((attack_run / "run.json").read_text())["scenes"]
    fresh = tmp_path / "never"
    cases = [(["--run", scenes, "--format", "commonroad", "--out", str(fresh)], f"--run {scenes}"),
             (["--run", str(attack_run), "--format", "lanelet2", "--out", str(fresh)], "--format 'lanelet2'"),
             (["--run", str(attack_run), "--format", "commonroad", "--out", str(out)], "pass --resume"),
             (["--run", str(attack_run), "--format", "commonroad", "--out", str(fresh), "--scene", "scene_9"],
              "--scene scene_9")]
    for case, expected in cases:
        assert exit_code(["export", *case]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("adversary export: error:") and expected in err[0], err
        assert not fresh.exists()


def test_highway_scene_gets_straight_lanelets_and_keeps_its_collision(tmp_path):
    """A highway-env scene (seed 500 episode 1, as tests/adversary/crash/test_attack_run.py) whose
    car ahead in the next lane cuts in and brakes (`braking_track`), the human replayed."""
    record = record_attack_scene(AttackScene("highway-v0", 500, 1))
    row = 1
    tracks = braking_track(record, row, into_ego_lane=True)[None]
    planner = cached_planner("replay")
    result = rollout(record, tracks, [row], planner, "replay")
    metrics = judge(record, tracks, [row], row, planner, "replay", result=result)
    assert metrics["collision"]
    attack = {"scene": asdict(record.scene), "planner": "replay", "selector": "hand-made", "status": "ok",
              "adversary_row": row, "adversary_log_id": int(record.agent_ids[row]), "collision": True,
              "metrics": metrics, "tracks": np.round(tracks, 3).tolist(),
              "ego_states": np.round(result.states[result.ego][result.valid[result.ego]], 6).tolist()}
    xml, side = write_commonroad(attack, record, tmp_path, "scene_00001")
    assert XMLFileWriter.check_validity_of_commonroad_file(xml.read_bytes())
    scenario, problems = XMLFileReader(str(xml)).open()
    sidecar = json.loads(side.read_text())

    lanelets = sorted(scenario.lanelet_network.lanelets, key=lambda la: la.lanelet_id)
    assert len(lanelets) == len(record.window.lanes) >= 2
    for lanelet, lane in zip(lanelets, record.window.lanes):
        width = np.linalg.norm(lanelet.left_vertices - lanelet.right_vertices, axis=1)
        assert np.allclose(width, lane.width_m)
        assert np.allclose(lanelet.center_vertices[:, 1], lane.centre[0, 1])     # straight, along x
    assert sum(la.adj_left is not None for la in lanelets) == len(lanelets) - 1
    k0, last = record.t0_step, sidecar["end_time_step"]
    for obstacle in scenario.dynamic_obstacles:
        assert obstacle.obstacle_id >= OBSTACLE_ID_OFFSET
        for k in range(last + 1):
            state = obstacle.state_at_time(k)
            if state is not None:               # every vehicle is on some lanelet's span along x
                assert any(la.center_vertices[0, 0] <= state.position[0] <= la.center_vertices[-1, 0]
                           for la in lanelets)
    [problem] = problems.planning_problem_dict.values()
    assert problem.planning_problem_id == OBSTACLE_ID_OFFSET + record.log.ego_id
    assert np.abs(np.asarray(problem.initial_state.position) - result.states[result.ego, k0, :2]).max() < 1e-6
    assert sidecar["adversary"]["obstacle_id"] == OBSTACLE_ID_OFFSET + int(record.agent_ids[row])
    assert sidecar["collision"]["recomputed_time_step"] == round(metrics["collision_time_s"] / 0.1) - k0
