"""Draw the example CRASH attack panels (`adversary.crash.panel.example_panels`).

    python experiments/crash_example_panels.py --out experiments/results/crash_panels_examples
"""

import argparse
import json
from pathlib import Path

from adversary.crash.panel import example_panels

parser = argparse.ArgumentParser(description="Draw the example attack panels.")
parser.add_argument("--out", default="experiments/results/crash_panels_examples")
args = parser.parse_args()
print(json.dumps(example_panels(Path(args.out)), indent=1))
