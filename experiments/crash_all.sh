#!/usr/bin/env bash
# Every CRASH run of experiments/crash_tables.py for one family, most important first; resumable.
# Usage: bash experiments/crash_all.sh highway|intersection [COUNT]
set -euo pipefail
family=$1
count=${2:-100}
py=${PYTHON:-python}
run() { $py experiments/crash_tables.py --family "$family" --count "$count" "$@"; }
run --part table3 --only idm:distance,idm:crash,idm:distance+mam,idm:crash-no-mam
run --part table1 --only replay:crash,replay:distance
run --part table1 --only riskmap:crash,riskmap:distance
$py experiments/crash_tables.py --family "$family" --count 30 --part k
run --part table3 --only idm:nearest,idm:random
$py experiments/crash_tables.py --part collect
