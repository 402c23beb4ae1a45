"""Rollout speed of the CRASH judge and the ego's offset from its log at t0, per planner.

    python experiments/crash_handover_offsets.py --env highway-v0 --episodes 10
"""

import argparse
import json

from adversary.crash.judge import handover_offsets

parser = argparse.ArgumentParser(description="Rollout speed and the ego's offset from its log at t0.")
parser.add_argument("--env", default="highway-v0")
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--episodes", type=int, default=10)
parser.add_argument("--planners", nargs="+", default=["replay", "idm", "riskmap:checkpoints/riskmap_highway"])
args = parser.parse_args()
print(json.dumps(handover_offsets(args.env, args.seed, args.episodes, tuple(args.planners)), indent=1))
