from pathlib import Path

import pytest

from adversary.campaign.config import campaign_from_dict
from adversary.campaign.run import RunOptions, run_campaign
from adversary.cli import main

TINY = {
    "name": "tiny", "seed": 0, "planners": ["cv", "idm"],
    "scenarios": [{"env": "highway-v0", "seed": 0, "episodes": 1},
                  {"env": "highway-v0", "seed": 1, "episodes": 1}],
    "attacks": [{"name": "natural"}, {"name": "aggressive_neighbour", "params": {"selection": "nearest"}},
                {"name": "nsga2_search",
                 "params": {"template": "cut_in", "pop": 4, "generations": 2, "episode_s": 6.0}}],
    "budget": {"episode_s": 3.0},
    "report": {"gallery": 2},
}


def tiny_config(**changes):
    return campaign_from_dict({**TINY, **changes})


@pytest.fixture(scope="session")
def tiny_campaign(tmp_path_factory) -> Path:
    """The tiny campaign (2 planners x 2 scenes x 3 attacks = 12 jobs) run uninterrupted, inline."""
    out = tmp_path_factory.mktemp("campaign") / "full"
    run_campaign(tiny_config(), out, RunOptions(progress=False))
    return out


def exit_code(argv: list[str]) -> int:
    """`adversary ARGV`'s exit status, argparse's usage errors (its SystemExit) included."""
    try:
        return main(argv)
    except SystemExit as stop:
        return stop.code
