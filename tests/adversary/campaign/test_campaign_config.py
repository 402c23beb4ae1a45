import pytest

from adversary.campaign.config import campaign_from_dict, load_campaign
from rasterize.errors import InputError
from tests.adversary.conftest import TINY


def test_tiny_config_lists_every_job_once():
    config = campaign_from_dict(TINY)
    jobs = config.jobs()
    assert len(jobs) == 2 * 2 * 3
    assert len({j.job_id for j in jobs}) == len(jobs)
    assert config.budget.episode_s == 3.0


@pytest.mark.parametrize("change, message", [
    ({"bogus": 1}, "unknown key 'bogus'"),
    ({"planners": []}, "planners must list at least one"),
    ({"scenarios": [{"env": "nope-v0"}]}, "unknown env 'nope-v0'"),
    ({"scenarios": [{"env": "highway-v0", "episodes": 0}]}, "episodes must be >= 1"),
    ({"scenarios": [{"env": "highway-v0", "episodes": "two"}]}, "episodes: expected int"),
    ({"scenarios": [{"env": "highway-v0", "planners": ["riskmap:x"]}]}, "not in the campaign's planners"),
    ({"attacks": [{"name": "strive"}]}, "unknown attack 'strive'"),
    ({"attacks": [{"name": "natural"}, {"name": "natural"}]}, "used twice"),
    ({"attacks": [{"name": "aggressive_neighbour", "params": {"speed": 3}}]}, "unknown key 'speed'"),
    ({"attacks": [{"name": "aggressive_neighbour", "params": {"selection": "random"}}]}, "softmin or nearest"),
    ({"attacks": [{"name": "aggressive_neighbour", "params": {"brake_mps2": -1}}]}, "must be positive"),
    ({"budget": {"episode_s": -1}}, "episode_s must be positive"),
    ({"budget": {"control_hz": 10, "replan_hz": 3}}, "multiple of replan_hz"),
    ({"safety": {"ttc": 1}}, "unknown key 'ttc'"),
])
def test_bad_configs_raise_one_line_input_errors(change, message):
    with pytest.raises(InputError) as info:
        campaign_from_dict({**TINY, **change})
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        load_campaign(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(InputError, match="not valid YAML"):
        load_campaign(bad)


def test_shipped_campaign_configs_validate():
    from pathlib import Path

    root = Path(__file__).resolve().parents[3] / "experiments" / "campaigns"
    for path in sorted(root.glob("*.yaml")):
        if path.name == "recorded.yaml":     # the user's CommonRoad files: test_recorded_family.py
            continue
        assert load_campaign(path).jobs()
