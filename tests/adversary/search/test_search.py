"""A tiny search runs, stores every evaluation, and resumes without driving anything again."""

import json

import numpy as np
import pytest

import adversary.search.run as search_module
from adversary.cli import main
from adversary.search.run import SearchConfig, evaluation_key, search
from rasterize.errors import InputError


@pytest.mark.slow
@pytest.mark.parametrize("algorithm", ["nsga2", "random"])
def test_tiny_search_stores_and_resumes(tmp_path, monkeypatch, algorithm):
    out = tmp_path / algorithm
    config = SearchConfig(planner="cv", template="lead_brakes", algorithm=algorithm, pop=4, gen=2,
                          episode_s=4.0)
    summary = search(config, out, progress=False)
    generations = [json.loads((out / "generations" / f"gen_{g:03d}.json").read_text())["keys"]
                   for g in range(2)]
    assert [len(keys) for keys in generations] == [4, 4]
    stored = sorted(p.stem for p in (out / "evaluations").glob("*.json"))
    assert stored == sorted(set(generations[0] + generations[1]))
    records = [json.loads((out / "evaluations" / f"{k}.json").read_text()) for k in stored]
    for record in records:
        assert evaluation_key(np.array(record["x"])) in stored
        assert record["feasible"] == (record["G"] <= 0)
        if record["feasible"]:
            assert (min(record["F"]) < -900) == record["collided"]
    assert summary["evaluations"] == 8
    assert summary["collisions"] == sum(r["collided"] for k in generations[0] + generations[1]
                                        for r in [json.loads((out / "evaluations" / f"{k}.json")
                                                             .read_text())])
    for name in ("collisions_per_generation.png", "best_failure_evolution.png", "pareto_front.png"):
        assert (out / name).stat().st_size > 1000
    if summary["collisions"]:
        assert list((out / "best_failure").glob("frame_*.png"))
    # every collision classified: the classes add up, none unknown
    f = summary["failures"]
    assert f["collisions"] == summary["collisions"] and f["unknown"] == 0
    assert f["at_fault"] + f["struck_from_behind"] + f["side"] == summary["collisions"]

    # Resume: the same vectors are asked for and all are read back; nothing is driven again.
    def must_not_drive(*args, **kwargs):
        raise AssertionError("a finished evaluation was driven again")

    monkeypatch.setattr(search_module, "evaluate", must_not_drive)
    again = search(config, out, resume=True, progress=False, frames=False)
    assert again["collisions_per_generation"] == summary["collisions_per_generation"]
    with pytest.raises(InputError, match="--resume"):
        search(config, out, progress=False)
    with pytest.raises(InputError, match="other settings"):
        search(SearchConfig(planner="cv", template="cut_in", algorithm=algorithm, pop=4, gen=2),
               out, resume=True, progress=False)


def test_cli_reports_bad_input_in_one_line(tmp_path, capsys):
    assert main(["search", "--planner", "nonsense", "--template", "cut_in", "--out",
                 str(tmp_path), "--pop", "2", "--gen", "1", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("adversary search: error: unknown planner spec") and "\n" not in err
    assert main(["search-report", "--out", str(tmp_path / "none")]) == 2


def test_cli_search_and_report_on_a_tiny_budget(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["search", "--planner", "cv", "--template", "cut_in", "--algorithm", "random",
                 "--pop", "2", "--gen", "1", "--episode-s", "2", "--out", str(out), "--quiet"]) == 0
    assert "of 2 evaluations collided" in capsys.readouterr().out
    assert len(list((out / "evaluations").glob("*.json"))) == 2
    assert main(["search-report", "--out", str(out), "--no-frames"]) == 0
    assert json.loads((out / "summary.json").read_text())["evaluations"] == 2


@pytest.mark.slow
def test_search_on_local_ray_gives_the_same_evaluations_as_local(tmp_path):
    pytest.importorskip("ray")
    config = SearchConfig(planner="cv", template="cut_in", algorithm="nsga2", pop=4, gen=2,
                          episode_s=3.0, workers=2)
    local = search(config, tmp_path / "local", progress=False, frames=False)
    on_ray = search(config, tmp_path / "ray", progress=False, frames=False, backend="ray")

    def evaluations(out):
        return {p.stem: json.loads(p.read_text())["F"] for p in (out / "evaluations").glob("*.json")}

    assert evaluations(tmp_path / "ray") == evaluations(tmp_path / "local")
    assert on_ray["collisions_per_generation"] == local["collisions_per_generation"]
    with pytest.raises(InputError, match="--backend"):
        search(config, tmp_path / "bad", progress=False, backend="cluster")
