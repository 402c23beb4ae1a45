#!/usr/bin/env bash
# Train the space-time planners at the largest scale a short loan of a GPU machine allows:
# collect on every core, train on the GPU, write the checkpoints (and their logs) to one folder
# to bring back. Everything is resumable: run it again with the same OUT to continue.
#
#   OUT=/path/to/out SCALE=full experiments/train_at_scale.sh     # one GPU, ~16 cores, ~10 min
#   OUT=/tmp/tiny    SCALE=tiny experiments/train_at_scale.sh     # the same steps in ~1 min on a CPU
#
# Settings (environment):
#   OUT        folder for data, runs and checkpoints (required)
#   SCALE      full | tiny (default full): episodes, epochs and devices below
#   US101, LANKERSHIM   folders of CommonRoad NGSIM scenario files (USA_US101-*_T-1.xml,
#              USA_Lanker-*_T-1.xml); the recorded families are skipped where unset
#   RISKMAP    the riskmap command (default .venv/bin/riskmap)
# Budget (SCALE=full, what the shipped checkpoints' notes quote): 2000 highway and 2000
# intersection episodes collected on all cores, 6 epochs each, batch 64 on the GPU.
set -euo pipefail
: "${OUT:?set OUT to the folder to write}"
SCALE=${SCALE:-full}
RISKMAP=${RISKMAP:-.venv/bin/riskmap}
CORES=$(nproc)
case "$SCALE" in
  full) EPISODES=2000; EPOCHS=6; BATCH=64; DEVICE=auto; RES=50; LIMIT=() ;;
  tiny) EPISODES=3;    EPOCHS=1; BATCH=4;  DEVICE=cpu;  RES=25; LIMIT=(--max-windows 8) ;;
  *) echo "SCALE must be full or tiny, got '$SCALE'" >&2; exit 2 ;;
esac
mkdir -p "$OUT/data" "$OUT/runs" "$OUT/checkpoints"
log() { echo "[$(date +%H:%M:%S)] $*"; }

# name  env-or-files  init-checkpoint  extra training flags
train_family() {
  local name=$1 data=$2 init=$3; shift 3
  log "train $name"
  "$RISKMAP" train --planner spacetime --data "$data" --out "$OUT/runs/$name" --epochs "$EPOCHS" \
      --batch-size "$BATCH" --lr 3e-4 --seed 0 --device "$DEVICE" --resolution "$RES" \
      --init-checkpoint "$init" "${LIMIT[@]}" --resume --quiet "$@"
  for ext in safetensors json; do
    cp "$OUT/runs/$name/best.$ext" "$OUT/checkpoints/$name.$ext"
  done
  cp "$OUT/runs/$name/log.csv" "$OUT/checkpoints/$name.log.csv"
}

init_for() {   # the spatial checkpoint a family starts from (at the tiny scale: a fresh tiny one)
  local spatial=$1 data=$2
  if [ "$SCALE" = full ]; then echo "checkpoints/$spatial"; return; fi
  "$RISKMAP" train --data "$data" --out "$OUT/runs/spatial_$spatial" --epochs 1 --batch-size 4 \
      --resolution "$RES" --device cpu --max-windows 8 --seed 0 --resume --quiet >/dev/null
  echo "$OUT/runs/spatial_$spatial/best"
}

log "collect highway-v0 and intersection-v0 ($EPISODES episodes each, $CORES workers)"
"$RISKMAP" collect --env highway-v0 --episodes "$EPISODES" --seed 1000 --out "$OUT/data/highway" \
    --workers "$CORES" --resume --quiet
"$RISKMAP" collect --env intersection-v0 --episodes "$EPISODES" --seed 1000 --out "$OUT/data/intersection" \
    --workers "$CORES" --resume --quiet
train_family riskmap_st_highway "$OUT/data/highway" "$(init_for riskmap_highway "$OUT/data/highway")"
if [ "$SCALE" = full ]; then PREDICT=(--predict-s 3); INTER=riskmap_intersection_yielding; else PREDICT=(); INTER=riskmap_intersection; fi
train_family riskmap_st_intersection "$OUT/data/intersection" \
    "$(init_for "$INTER" "$OUT/data/intersection")" "${PREDICT[@]}"
if [ -n "${US101:-}" ]; then
  "$RISKMAP" collect --from-commonroad "$US101" --out "$OUT/data/us101" --resume --quiet
  train_family riskmap_st_us101 "$OUT/data/us101" checkpoints/riskmap_us101 --val-groups 15,16,17,18
fi
if [ -n "${LANKERSHIM:-}" ]; then
  "$RISKMAP" collect --from-commonroad "$LANKERSHIM" --out "$OUT/data/lankershim" --resume --quiet
  train_family riskmap_st_lankershim "$OUT/data/lankershim" checkpoints/riskmap_lankershim --predict-s 3 \
      --val-groups "USA_Lanker-2_1+2+3+4+16+19+21,USA_Lanker-2_15+23"
fi
log "done: $OUT/checkpoints"
ls -l "$OUT/checkpoints"
