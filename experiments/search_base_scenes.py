"""Drive every template's base scene (all parameters neutral) with each planner.

    python experiments/search_base_scenes.py idm riskmap:checkpoints/riskmap_highway
A search only means something if the base scene itself is passed without a collision.
"""

from __future__ import annotations

import sys

from adversary.search.evaluation import EvaluationConfig, evaluate
from adversary.search.scenarios import TEMPLATES


def main(planners: list[str]) -> None:
    import torch

    torch.set_num_threads(1)
    print("| planner | template | collided | off road | journey (m) | min gap (m) |")
    print("|---|---|---|---|---|---|")
    for planner in planners:
        for name, template in TEMPLATES.items():
            r = evaluate(template, template.neutral, EvaluationConfig(planner, name))
            print(f"| {planner} | {name} | {r['collided']} | {r['off_road']} | {r['journey_m']:.0f} | "
                  f"{'-' if r['min_gap_m'] is None else format(r['min_gap_m'], '.1f')} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or ["idm", "riskmap:checkpoints/riskmap_highway"])
