"""`rasterize.commonroad_compat`: the one door to commonroad-io, protobuf-free, for every release.

These run under the installed release (`make test`) and under the oldest supported one
(`make test-commonroad-oldest`)."""

from __future__ import annotations

import ast
import importlib.metadata
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("commonroad")

from rasterize.commonroad_compat import (
    COMMONROAD_VERSION,
    CustomState,
    DynamicObstacle,
    GoalRegion,
    InitialState,
    Interval,
    Lanelet,
    LaneletType,
    ObstacleType,
    OverwriteExistingFile,
    PlanningProblem,
    PlanningProblemSet,
    Scenario,
    ScenarioID,
    Trajectory,
    TrajectoryPrediction,
    XMLFileReader,
    XMLFileWriter,
    rect_region,
    rect_shape,
    region_contains,
)

ROOT = Path(__file__).resolve().parents[2]
RECORDING = ROOT / "tests" / "fixtures" / "commonroad" / "USA_US101-4_1_T-1.xml"


def test_the_release_imported_is_the_one_installed_and_expected():
    """The imported package is the distribution whose version is reported, and, where
    COMMONROAD_IO_EXPECTED names one (`make test-commonroad-oldest`), that release: a PYTHONPATH
    overlay that failed to shadow the venv's copy would test the wrong version."""
    import commonroad

    dist = importlib.metadata.distribution("commonroad-io")
    assert Path(commonroad.__file__).resolve().is_relative_to(Path(dist.locate_file("")).resolve())
    assert COMMONROAD_VERSION == dist.version
    expected = os.environ.get("COMMONROAD_IO_EXPECTED")
    if expected:
        assert COMMONROAD_VERSION == expected, commonroad.__file__


def test_only_the_compat_module_imports_commonroad():
    offenders = []
    for package in ("rasterize", "riskmap", "adversary"):
        for path in sorted((ROOT / package).rglob("*.py")):
            if path.name == "commonroad_compat.py":
                continue
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                         else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                         else [])
                offenders += [f"{path.relative_to(ROOT)}:{node.lineno}" for n in names
                              if n == "commonroad" or n.startswith("commonroad.")]
    assert offenders == []


def test_reading_and_writing_xml_imports_no_protobuf():
    """A fresh interpreter reads a recording and loads the exporter's and the renderer's classes:
    commonroad-io's protobuf modules (which the installed protobuf runtime cannot load) stay out."""
    code = f"""
import json, sys
from rasterize.commonroad import RecordedTraffic, load_scenario
import rasterize.commonroad_compat as compat
import adversary.export.commonroad
traffic = RecordedTraffic(load_scenario({str(RECORDING)!r}))
compat.mp_renderer()
loaded = [m for m in sys.modules if m.startswith(("google.protobuf", "commonroad"))]
print(json.dumps(loaded))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert "commonroad.common.reader.file_reader_xml" in loaded
    assert [m for m in loaded if m.startswith("google.protobuf") or "protobuf" in m or m.endswith("_pb2")
            or m in ("commonroad.common.file_reader", "commonroad.common.file_writer")] == []


def test_rectangles_round_trip_through_the_xml_writer_and_reader(tmp_path):
    """The helpers whose classes moved between releases: an obstacle's box and a goal region."""
    shape = rect_shape(length=4.5, width=1.8)
    states = [InitialState(time_step=k, position=np.array([2.0 * k, 1.0]), orientation=0.0, velocity=20.0,
                           acceleration=0.0, yaw_rate=0.0, slip_angle=0.0) for k in range(3)]
    obstacle = DynamicObstacle(7, ObstacleType.CAR, shape, states[0],
                               TrajectoryPrediction(Trajectory(1, states[1:]), shape))
    scenario = Scenario(0.1, ScenarioID(country_id="ZAM", map_name="Compat", map_id=1))
    x = np.linspace(0.0, 50.0, 6)
    scenario.add_objects(Lanelet(np.column_stack([x, x * 0 + 2.75]), np.column_stack([x, x * 0 + 1.0]),
                                 np.column_stack([x, x * 0 - 0.75]), 100,
                                 lanelet_type={LaneletType.HIGHWAY}))      # the schema wants a road
    scenario.add_objects(obstacle)
    region = rect_region([30.0, 1.0], length=10.0, width=3.5, orientation=0.0)
    goal = GoalRegion([CustomState(time_step=Interval(0, 20), position=region)])
    problems = PlanningProblemSet([PlanningProblem(1, states[0], goal)])
    path = tmp_path / "compat.xml"
    XMLFileWriter(scenario, problems, "test", "", "test", set(), decimal_precision=8).write_to_file(
        str(path), OverwriteExistingFile.ALWAYS)
    assert XMLFileWriter.check_validity_of_commonroad_file(path.read_bytes())

    read, read_problems = XMLFileReader(str(path)).open()
    [back] = read.dynamic_obstacles
    assert (back.obstacle_shape.length, back.obstacle_shape.width) == (4.5, 1.8)
    np.testing.assert_allclose(back.state_at_time(2).position, [4.0, 1.0])
    [problem] = read_problems.planning_problem_dict.values()
    region = problem.goal.state_list[0].position
    assert region_contains(region, [30.0, 1.0]) and region_contains(region, [34.9, 2.7])
    assert not region_contains(region, [35.5, 1.0]) and not region_contains(region, [30.0, 3.0])
