"""Guard windows from a search run: every feasible evaluation driven again, with its own outcome."""

import json

import numpy as np
import pytest

from adversary.search.guard_data import export_search
from adversary.search.run import SearchConfig, search
from rasterize.errors import InputError
from riskmap.guard.dataset import load_split


@pytest.fixture(scope="module")
def search_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("search") / "run"
    # seed 0: two of the three training scenarios end in a cut-in collision
    search(SearchConfig(planner="cv", template="cut_in", algorithm="random", pop=6, gen=1, seed=0,
                        episode_s=6.0), out, progress=False, frames=False)
    return out


def test_each_feasible_evaluation_becomes_one_job_with_the_search_outcome(search_run, tmp_path):
    records = [json.loads(p.read_text()) for p in sorted((search_run / "evaluations").glob("*.json"))]
    feasible = [r for r in records if r["feasible"]]
    metas = export_search([search_run], tmp_path, "train", val_fraction=0.5, progress=False)
    assert len(metas) == len(feasible)
    # the re-drive meets the search's own verdict (same planner, seed and template)
    assert [m["collided"] for m in metas] == [m["search_collided"] for m in metas]
    assert [m["search_collided"] for m in metas] == [r["collided"] for r in feasible]
    assert sorted(m["split"] for m in metas) == sorted(["train"] * (len(feasible) - round(0.5 * len(feasible)))
                                                       + ["val"] * round(0.5 * len(feasible)))
    windows = load_split(tmp_path, "train", 3.0)
    crashed = sum(m["collided"] for m in metas if m["split"] == "train")
    # a crash gives the target's windows over the 3 s before it (0.1 s apart); none otherwise
    assert windows["label"].sum() == sum(m["positives"] for m in metas if m["split"] == "train")
    assert crashed == 2 and windows["label"].sum() == 2 * 30
    assert np.isfinite(windows["ttc_s"][windows["label"] == 1]).all()


def test_a_second_export_needs_resume_and_then_skips_the_written_jobs(search_run, tmp_path):
    first = export_search([search_run], tmp_path, "train", progress=False)
    with pytest.raises(InputError, match="--resume"):
        export_search([search_run], tmp_path, "train", progress=False)
    again = export_search([search_run], tmp_path, "train", resume=True, progress=False)
    assert again == first


def test_a_directory_that_is_no_search_run_is_refused(tmp_path):
    with pytest.raises(InputError, match="adversary search --out"):
        export_search([tmp_path], tmp_path / "out", "train", progress=False)
