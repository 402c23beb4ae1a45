"""`riskmap tune-goal-variance`: open-loop plan quality per candidate, the best one in the sidecar."""

import json

from riskmap.cli import main
from riskmap.evaluation.open_loop import evaluate


def test_tune_goal_variance_writes_the_lowest_ade_candidate(tiny_checkpoint, tiny_dataset, tmp_path, capsys):
    checkpoint = tmp_path / "best"
    for suffix in (".safetensors", ".json"):
        checkpoint.with_suffix(suffix).write_bytes(tiny_checkpoint.with_suffix(suffix).read_bytes())
    assert main(["tune-goal-variance", "--checkpoint", str(checkpoint), "--data", str(tiny_dataset),
                 "--candidates", "5,1", "--limit", "3"]) == 0
    planning = json.loads(checkpoint.with_suffix(".json").read_text())["planning"]
    ades = {row["goal_variance"]: row["ade_m"] for row in planning["candidates"]}
    assert set(ades) == {5.0, 1.0} and planning["goal_variance"] == min(ades, key=ades.get)
    # The recorded choice is what the planner now plans with, and the numbers are reproducible.
    again = evaluate(checkpoint.with_suffix(".safetensors"), tiny_dataset, 3)
    assert again["goal_variance"] == planning["goal_variance"]
    assert abs(again["ade_m"]["mean"] - ades[planning["goal_variance"]]) < 1e-9
    assert "chosen goal variance" in capsys.readouterr().out


def test_bad_candidates_are_one_line(tiny_checkpoint, tiny_dataset, capsys):
    assert main(["tune-goal-variance", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_dataset),
                 "--candidates", "5,x", "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("riskmap tune-goal-variance: error: --candidates") and "\n" not in err
