#!/bin/bash
# Run from the repository root: PYTHON=path/to/python bash experiments/kill_resume_check.sh
# Kill a campaign with SIGKILL once 3 records exist, resume it, compare with an uninterrupted run.
set -u
rm -rf out/kill_resume
PY=${PYTHON:-.venv/bin/python}
export PYTHONPATH=$PWD OMP_NUM_THREADS=1
$PY -m adversary stress-test --config experiments/campaigns/tiny.yaml --out out/kill_resume/killed --quiet &
pid=$!
while [ "$(ls out/kill_resume/killed/records 2>/dev/null | wc -l)" -lt 3 ]; do sleep 0.2; done
kill -9 $pid; wait $pid 2>/dev/null
echo "killed after $(ls out/kill_resume/killed/records | wc -l) records"
$PY -m adversary stress-test --config experiments/campaigns/tiny.yaml --out out/kill_resume/killed --resume --quiet
$PY -m adversary stress-test --config experiments/campaigns/tiny.yaml --out out/kill_resume/full --quiet
$PY -m adversary report out/kill_resume/killed && $PY -m adversary report out/kill_resume/full
$PY -c "
import json
a = json.load(open('out/kill_resume/killed/report.json'))['results']; b = json.load(open('out/kill_resume/full/report.json'))['results']
for x in (a, b):
    x.pop('gallery_images')
print('results identical:', a == b)"
