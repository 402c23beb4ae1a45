"""The report read at a glance: the headline chart and the summary paragraph at the top, a page
per job with its record, animated GIFs of the worst collisions, complete frame strips, and risk
maps over time for a planner that makes them."""

import html
import json
import re
from dataclasses import replace

import numpy as np
import pytest

from adversary.campaign.run import RunOptions, run_campaign
from adversary.campaign.store import ResultStore
from adversary.report.check import page_summary, site_problems
from adversary.report.frames import (
    GIF_MAX_FRAMES,
    STRIP_SLOTS,
    animation_frames,
    gif_frame_count,
    load_artifact,
    recorded_indices,
    strip_indices,
)
from adversary.report.jobs import job_media
from adversary.report.page import make_report
from rasterize.scene_io import pack_scenes
from tests.adversary.conftest import tiny_config

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def report(tiny_campaign, tmp_path_factory):
    out = tmp_path_factory.mktemp("glance") / "report"
    return out, make_report(tiny_campaign, out)


def _records(campaign):
    store = ResultStore(campaign)
    records = store.records()
    store.close()
    return records


def test_headline_chart_and_summary_come_first(report):
    out, saved = report
    text = (out / "report.html").read_text()
    first_table = text.index("<table")
    assert text.index('id="summary"') < first_table and text.index('id="headline"') < first_table
    assert saved["images"]["headline"] == "figures/headline.png"
    assert page_summary(out / "report.html")["images"][0] == "figures/headline.png"
    lead, summary = saved["results"]["summary"]["lead"], saved["results"]["summary"]["text"]
    collisions = saved["results"]["summary_collisions"]["text"]
    assert html.escape(summary, quote=False) in text and html.escape(collisions, quote=False) in text
    # The failures that count lead, every collision follows: the lead sentence's counts are the
    # comparison rows' classes summed.
    assert text.index(html.escape(lead, quote=False)) < text.index(html.escape(collisions, quote=False))
    classes = [r["failure_classes"] for r in saved["results"]["comparison"]]
    assert lead.startswith(f"Of {sum(c['collisions'] for c in classes)} collisions in 12 finished jobs, "
                           f"{sum(c['counted'] for c in classes)} count")
    # Each paragraph quotes the by-family rows: each planner's worst cell with its interval.
    for paragraph, metric in ((summary, "failure_rate"), (collisions, "collision_rate")):
        for planner in ("cv", "idm"):
            rows = [r for r in saved["results"]["by_family"] if r["planner"] == planner]
            rate = max(rows, key=lambda r: r[metric]["value"])[metric]
            assert f"{planner} " in paragraph
            assert f"{100 * rate['hi']:.0f}%" in paragraph if rate["k"] == 0 else \
                f"{100 * rate['value']:.0f}% [{100 * rate['lo']:.0f}, {100 * rate['hi']:.0f}]" in paragraph
        assert "too wide to rank" in paragraph and "2 jobs per planner" in paragraph   # 2 scenes per cell


def test_a_page_per_job_with_its_record(report, tiny_campaign):
    out, saved = report
    records = _records(tiny_campaign)
    links = page_summary(out / "report.html")["links"]
    for record in records:
        page = out / "jobs" / f"{record['job_id']}.html"
        assert f"jobs/{record['job_id']}.html" in links
        shown = re.search(r'<pre id="record">(.*?)</pre>', page.read_text(), re.DOTALL).group(1)
        assert json.loads(html.unescape(shown)) == record
        assert '<a href="../report.html">' in page.read_text()
    assert saved["pages"] == {r["job_id"]: f"jobs/{r['job_id']}.html" for r in records}
    assert site_problems(out / "report.html") == []


def test_worst_collisions_are_animated(report):
    out, saved = report
    gallery = saved["results"]["gallery_images"]
    worst = {w["job_id"]: w for w in saved["results"]["worst"]}
    collided = [g for g in gallery if worst[g["job_id"]]["collided"]]
    assert collided, "the tiny campaign has collisions among its worst scenes"
    for g in collided:
        gif = out / g["gif"]
        assert gif_frame_count(gif) >= 5                    # 5 fps over at least a second
        assert gif.stat().st_size < 1_000_000
        assert g["gif"] in page_summary(out / "report.html")["images"]
        job_page = out / g["page"]
        assert g["gif"].removeprefix("jobs/") in page_summary(job_page)["images"]


def test_frame_strips_are_complete(report, tiny_campaign):
    out, _ = report
    for record in _records(tiny_campaign):
        art = load_artifact(tiny_campaign / "artifacts" / f"{record['job_id']}.npz")
        final = art.final
        assert final.dt == pytest.approx(0.1)               # every recorded step is stored
        picks = strip_indices(final)
        assert len(picks) == STRIP_SLOTS
        assert final.valid[final.ego_index, picks].all()    # no slot without a recorded scene
        span = (picks[-1] - picks[0]) * final.dt
        episode = (len(recorded_indices(final)) - 1) * final.dt
        assert span == pytest.approx(min(3.0, episode))
        assert (out / "jobs" / "media" / f"{record['job_id']}_strip.png").is_file()
    assert "not recorded" not in (out / "report.html").read_text()


def test_stores_of_before_the_frames_still_draw(tiny_campaign, tmp_path):
    """Older artifacts hold the final scene at 0.5 s steps and no plans__ arrays."""
    record = next(r for r in _records(tiny_campaign) if r["collided"])
    source = tiny_campaign / "artifacts" / f"{record['job_id']}.npz"
    art = load_artifact(source)
    final = art.final
    keep = np.arange(final.current_index % 5, final.current_index + 1, 5)
    old = replace(final, states=final.states[:, keep], valid=final.valid[:, keep],
                  current_index=len(keep) - 1, dt=0.5)
    with np.load(source) as data:
        arrays = {k: data[k] for k in data.files if not k.startswith("final__")}
    arrays.update({f"final__{k}": v for k, v in pack_scenes([old]).items()})
    np.savez_compressed(tmp_path / "old.npz", **arrays)
    media = job_media(tmp_path / "old.npz", record, tmp_path / "out", animate=True)
    assert media["strip"] and media["gif_frames"] >= 2
    assert len(strip_indices(load_artifact(tmp_path / "old.npz").final)) >= 2


def test_risk_maps_over_time_and_beside_the_animation(tmp_path):
    config = tiny_config(name="risk", planners=["riskmap:checkpoints/riskmap_highway"],
                         scenarios=[{"env": "highway-v0", "seed": 0, "episodes": 1}],
                         attacks=[{"name": "natural"}], budget={"episode_s": 2.0})
    run_campaign(config, tmp_path / "c", RunOptions(progress=False))
    [record] = _records(tmp_path / "c")
    artifact = tmp_path / "c" / "artifacts" / f"{record['job_id']}.npz"
    art = load_artifact(artifact)
    assert art.risk_maps is not None and len(art.risk_maps) == record["plan_calls"] >= 2
    assert np.all(np.diff(art.risk_times_s) > 0)
    frames, _ = animation_frames(art, record["env_id"], "t", None)
    bev_only, _ = animation_frames(replace(art, risk_maps=None, risk_times_s=None), record["env_id"], "t", None)
    assert 2 <= len(frames) <= GIF_MAX_FRAMES
    assert frames[0].shape[1] > 1.8 * bev_only[0].shape[1]    # the risk map beside the BEV
    out = tmp_path / "report"
    make_report(tmp_path / "c", out)
    page = out / "jobs" / f"{record['job_id']}.html"
    assert f"media/{record['job_id']}_risk.png" in page_summary(page)["images"]
    assert site_problems(out / "report.html") == []
