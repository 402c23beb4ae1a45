"""The --out rule every long command applies (riskmap.infra.rundir)."""

import json

import pytest

from rasterize.errors import InputError
from riskmap.infra.rundir import claim_out_dir, refuse_unless_resume

SETTINGS = {"config": {"env_id": "highway-v0", "episodes": 2, "seed": 0}, "planner": "cv"}


def _claim(out, settings=SETTINGS, resume=False):
    return claim_out_dir(out, holds="driven episodes", marker="episodes", resume=resume,
                         settings_file="run.json", settings=settings, may_change=("config.episodes",))


def test_a_fresh_run_writes_its_settings_with_provenance(tmp_path):
    assert _claim(tmp_path / "run") is None
    written = json.loads((tmp_path / "run" / "run.json").read_text())
    assert written["planner"] == "cv" and "git_commit" in written and "package_version" in written


def test_work_already_there_needs_resume(tmp_path):
    _claim(tmp_path)
    (tmp_path / "episodes").mkdir()
    (tmp_path / "episodes" / "episode_000000.json").write_text("{}")
    with pytest.raises(InputError, match="already holds driven episodes; pass --resume"):
        _claim(tmp_path)
    # An empty marker directory is no work: a fresh start is fine.
    refuse_unless_resume(tmp_path, "x", "nothing_here", resume=False)


def test_resume_allows_only_the_keys_that_may_change(tmp_path):
    _claim(tmp_path)
    more = {**SETTINGS, "config": {**SETTINGS["config"], "episodes": 5}}
    assert _claim(tmp_path, more, resume=True)["planner"] == "cv"
    other = {**SETTINGS, "config": {**SETTINGS["config"], "seed": 1}}
    with pytest.raises(InputError, match="other settings"):
        _claim(tmp_path, other, resume=True)
    with pytest.raises(InputError, match="other settings"):
        _claim(tmp_path, {**SETTINGS, "goal_variance": 2.0}, resume=True)


def test_unreadable_settings_are_one_line(tmp_path):
    (tmp_path / "run.json").write_text("{not json")
    with pytest.raises(InputError, match="unreadable"):
        _claim(tmp_path, resume=True)


def test_a_second_writer_of_the_same_out_stops_at_once(tmp_path):
    import subprocess
    import sys

    out = tmp_path / "run"
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time; from riskmap.infra.rundir import lock_out_dir; "
         f"lock_out_dir({str(out)!r}); print('held', flush=True); time.sleep(30)"],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(InputError, match="being written by another run"):
            claim_out_dir(out, holds="x", marker="run.json", resume=True, settings_file="run.json",
                          settings={"a": 1})
        assert not (out / "run.json").exists()
    finally:
        holder.kill()
        holder.wait()
    # The holder is gone (killed: the system released its lock): the directory can be claimed,
    # and claimed again by the same process.
    for _ in range(2):
        claim_out_dir(out, holds="x", marker="run.json", resume=True, settings_file="run.json",
                      settings={"a": 1})
    assert (out / "run.json").exists()


def test_collect_and_train_take_the_lock_too(tmp_path):
    """A second `collect --resume` (or `train --resume`) on a folder another run is writing stops
    at once with one line and writes nothing."""
    import subprocess
    import sys

    from riskmap.data.collect import CollectConfig, collect
    from riskmap.training.config import TrainConfig
    from riskmap.training.train import train

    data, run = tmp_path / "data", tmp_path / "run"
    hold = "print('held', flush=True); time.sleep(30)"
    holders = [
        subprocess.Popen([sys.executable, "-c",                  # a collection still running
                          "import time; from riskmap.data.collect import CollectConfig, collect; "
                          f"collect(CollectConfig('intersection-v0', 2, seed=3), {str(data)!r}, "
                          f"progress=False); {hold}"], stdout=subprocess.PIPE, text=True),
        subprocess.Popen([sys.executable, "-c",                  # a training run starting
                          "import time; from riskmap.infra.rundir import lock_out_dir; "
                          f"lock_out_dir({str(run)!r}); {hold}"], stdout=subprocess.PIPE, text=True),
    ]
    try:
        assert all(h.stdout.readline().strip() == "held" for h in holders)
        before = sorted(p.name for p in data.rglob("*"))
        with pytest.raises(InputError, match="being written by another run"):
            collect(CollectConfig("intersection-v0", 2, seed=3), data, resume=True, progress=False)
        assert sorted(p.name for p in data.rglob("*")) == before
        with pytest.raises(InputError, match="being written by another run"):
            train(TrainConfig(data=str(data), out=str(run), epochs=1, max_windows=2), resume=False,
                  progress=False)
        assert sorted(p.name for p in run.iterdir()) == [".lock"]
    finally:
        for h in holders:
            h.kill()
            h.wait()


def test_every_other_long_writer_takes_the_lock(tmp_path):
    """Traffic-model and selector training, the scenario search, guard training and the campaign:
    resumed on a folder another run is writing, each stops at once with one line and writes
    nothing (without --resume the folder's content already stops them)."""
    import subprocess
    import sys

    from adversary.campaign.config import load_campaign
    from adversary.campaign.run import RunOptions, run_campaign
    from adversary.crash.train_selector import train_selector
    from adversary.crash.train_traffic import train_traffic
    from adversary.search.run import SearchConfig, search
    from riskmap.guard.train import train as train_guard

    names = ("traffic", "selector", "search", "guard", "campaign")
    outs = {name: tmp_path / name for name in names}
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import time; from riskmap.infra.rundir import lock_out_dir; "
         + "".join(f"lock_out_dir({str(p)!r}); " for p in outs.values())
         + "print('held', flush=True); time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    config = tmp_path / "campaign.yaml"
    config.write_text("name: locked\nseed: 0\nplanners: [idm]\n"
                      "scenarios: [{env: highway-v0, seed: 0, episodes: 1}]\n"
                      "attacks: [{name: natural}]\n")
    calls = {
        "traffic": lambda: train_traffic([tmp_path / "nowhere"], outs["traffic"], resume=True,
                                         progress=False),
        "selector": lambda: train_selector(tmp_path / "nowhere", [tmp_path / "nowhere"],
                                           outs["selector"], resume=True, progress=False),
        "search": lambda: search(SearchConfig(planner="idm", template="cut_in", pop=2, gen=1),
                                 outs["search"], resume=True, progress=False, frames=False),
        "guard": lambda: train_guard(tmp_path / "nowhere", outs["guard"], resume=True,
                                     progress=False),
        "campaign": lambda: run_campaign(load_campaign(config), outs["campaign"],
                                         RunOptions(resume=True, progress=False)),
    }
    try:
        assert holder.stdout.readline().strip() == "held"
        for name in names:
            with pytest.raises(InputError, match="being written by another run"):
                calls[name]()
            assert sorted(p.name for p in outs[name].iterdir()) == [".lock"], name
    finally:
        holder.kill()
        holder.wait()
