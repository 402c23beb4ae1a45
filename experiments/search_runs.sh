#!/usr/bin/env bash
# NSGA-II versus random search at equal budgets, two templates, two planners.
# Usage: experiments/search_runs.sh PLANNER_NAME POP GEN WORKERS [ROOT]  (PLANNER_NAME: idm | riskmap)
# Results under ROOT (default out/search); rerunning continues (--resume) without re-driving finished scenes.
set -euo pipefail
name=$1; pop=$2; gen=$3; workers=$4; root=${5:-out/search}
case $name in
  idm) spec=idm ;;
  riskmap) spec=riskmap:checkpoints/riskmap_highway ;;
  *) echo "unknown planner name $name" >&2; exit 2 ;;
esac
for template in lead_brakes cut_in; do
  for algorithm in nsga2 random; do
    python -m adversary search --planner "$spec" --template "$template" --algorithm "$algorithm" \
      --pop "$pop" --gen "$gen" --seed 0 --workers "$workers" --quiet --resume \
      --out "$root/${name}_${template}_${algorithm}"
  done
done
