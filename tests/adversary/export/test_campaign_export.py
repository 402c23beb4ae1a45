"""`adversary export --run CAMPAIGN_DIR`: a stress-test campaign's attacked crash jobs written as
CommonRoad scenarios with the attack runs' writer, read back with commonroad-io, the collision
step the job's record's; other jobs listed with why; the report's job pages name the command."""

import html
import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from adversary.attacks.crash import EXPORT_KEYS
from adversary.attacks.recorded import recorded_env_id
from adversary.campaign.config import campaign_from_dict
from adversary.campaign.run import RunOptions, run_campaign
from adversary.cli import main
from adversary.export.campaign import OLD_JOB, export_command
from adversary.export.commonroad import exported_collision_step
from adversary.report.page import make_report
from rasterize.commonroad_compat import XMLFileReader
from tests.adversary.conftest import exit_code

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"
RECORDING = FIXTURES / "USA_US101-4_1_T-1.xml"
ENV = recorded_env_id("us101")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory) -> Path:
    """cv on highway-env seed 500 episode 0 (crash: collides with the adversary), idm on the
    fixture recording's first scene (crash, and natural: not exportable); about 20 s."""
    data = {"name": "export", "seed": 0, "planners": ["cv", "idm"],
            "scenarios": [{"env": "highway-v0", "seed": 500, "episodes": 1, "planners": ["cv"]},
                          {"commonroad": str(RECORDING), "episodes": 1, "planners": ["idm"]}],
            "attacks": [{"name": "natural", "envs": [ENV]},
                        {"name": "crash", "params": {"selector": "nearest", "iterations": 10,
                                                     "replan_every": 10}}],
            "budget": {"episode_s": 3.0}, "report": {"gallery": 1}}
    out = tmp_path_factory.mktemp("campaign_export") / "campaign"
    counts = run_campaign(campaign_from_dict(data), out, RunOptions(progress=False))
    assert counts["failed"] == 0 and counts["finished"] == 3
    return out


def _records(campaign: Path) -> dict[str, dict]:
    records = [json.loads(p.read_text()) for p in (campaign / "records").glob("*.json")]
    return {f"{r['attack']}@{r['env_id']}": r for r in records}


def test_crash_jobs_export_and_keep_their_collision_step(campaign, tmp_path):
    records = _records(campaign)
    crash = [records["crash@highway-v0"], records[f"crash@{ENV}"]]
    natural = records[f"natural@{ENV}"]
    assert all(r["attacked"] for r in crash) and records["crash@highway-v0"]["collided_with_adversary"]
    out = tmp_path / "exported"
    argv = ["export", "--run", str(campaign), "--format", "commonroad", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    index = json.loads((out / "index.json").read_text())
    assert sorted(e["job"] for e in index["exported"]) == sorted(r["job_id"] for r in crash)
    assert [s["job"] for s in index["skipped"]] == [natural["job_id"]]
    assert "natural job keeps no generated adversary trajectory" in index["skipped"][0]["why"]
    for record in crash:
        xml = out / f"{record['job_id']}.xml"
        scenario, problems = XMLFileReader(str(xml)).open()
        sidecar = json.loads(xml.with_suffix(".json").read_text())
        assert sidecar["source"]["job_id"] == record["job_id"] and sidecar["planner"] == record["planner"]
        assert scenario.obstacle_by_id(sidecar["adversary"]["obstacle_id"]) is not None
        assert list(problems.planning_problem_dict) == [sidecar["planning_problem_id"]]
        k0 = sidecar["time_step_0"]["log_step"]
        expected = (round(record["collision_time_s"] / sidecar["dt_s"]) - k0
                    if record["collided_with_adversary"] else None)
        assert exported_collision_step(xml) == sidecar["collision"]["time_step"] == expected


def test_only_failures_job_resume_and_old_campaigns(campaign, tmp_path, capsys):
    records = _records(campaign)
    hit = records["crash@highway-v0"]
    out = tmp_path / "one"
    args = ["export", "--run", str(campaign), "--format", "commonroad", "--out", str(out), "--quiet",
            "--job", hit["job_id"]]
    assert main([*args, "--only-failures"]) == 0
    assert [e["job"] for e in json.loads((out / "index.json").read_text())["exported"]] == \
        ([hit["job_id"]] if hit["failure"] is not None else [])
    assert main([*args, "--only-failures", "--resume"]) == 0
    capsys.readouterr()

    # a campaign from before export existed: its crash artifacts lack the export arrays
    old = tmp_path / "old"
    (old / "records").mkdir(parents=True)
    (old / "artifacts").mkdir()
    (old / "campaign.json").write_bytes((campaign / "campaign.json").read_bytes())
    for path in (campaign / "records").glob("*.json"):
        (old / "records" / path.name).write_bytes(path.read_bytes())
    for path in (campaign / "artifacts").glob("*.npz"):
        with np.load(path) as data:
            kept = {k: data[k] for k in data.files if k not in EXPORT_KEYS}
        np.savez_compressed(old / "artifacts" / path.name, **kept)
    artifact = old / "artifacts" / f"{hit['job_id']}.npz"
    assert export_command(old, hit, artifact) is None
    assert export_command(campaign, hit, campaign / "artifacts" / f"{hit['job_id']}.npz") is not None
    fresh = tmp_path / "never"
    cases = [(["--run", str(old)], "none of its 3 finished jobs can be exported ("),
             (["--run", str(old)], OLD_JOB),
             (["--run", str(campaign), "--job", "nope"], "--job nope is not a finished job"),
             (["--run", str(campaign), "--scene", "scene_00000"], "--scene is for `adversary attack` runs")]
    for case, expected in cases:
        assert exit_code(["export", *case, "--format", "commonroad", "--out", str(fresh)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and expected in err[0], err
        assert not fresh.exists()


def test_report_job_page_shows_the_export_command(campaign, tmp_path):
    report = make_report(campaign, tmp_path / "report")
    records = _records(campaign)
    page = (tmp_path / "report" / report["pages"][records[f"crash@{ENV}"]["job_id"]]).read_text()
    [command] = re.findall(r'<pre id="export">(.*?)</pre>', page, re.S)
    argv = shlex.split(html.unescape(command))
    assert argv[:2] == ["adversary", "export"] and records[f"crash@{ENV}"]["job_id"] in argv
    natural = (tmp_path / "report" / report["pages"][records[f"natural@{ENV}"]["job_id"]]).read_text()
    assert 'id="export"' not in natural
    assert main([*argv[1:], "--quiet"]) == 0          # the command on the page works as shown
    out = Path(argv[argv.index("--out") + 1])
    assert (out / f"{records[f'crash@{ENV}']['job_id']}.xml").is_file()
