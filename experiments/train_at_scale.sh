#!/usr/bin/env bash
# Train the space-time planners at the largest scale a short loan of a GPU machine allows:
# collect on the machine's cores while the recorded families train, then train the simulated
# families on the GPU side by side, each raster size beside the other, until a deadline; write
# the checkpoints (and their logs) to one folder to bring back. Everything is resumable: run it
# again with the same OUT to continue.
#
#   OUT=/path/to/out SCALE=full experiments/train_at_scale.sh     # one GPU, ~16 cores, ~10 min
#   OUT=/tmp/tiny    SCALE=tiny experiments/train_at_scale.sh     # the same steps in ~2 min on a CPU
#
# Settings (environment):
#   OUT          folder for data, runs and checkpoints (required)
#   SCALE        full | tiny (default full): episodes, epochs and devices below
#   DEADLINE_S   seconds after the start at which every training stops (default: 540 at full
#                scale, none at tiny); each run keeps its best finished epoch, so a run cut short
#                by the deadline still ships (its log says how many epochs it finished)
#   RASTERS      raster sizes to train, pixels a side (default "200 100"); 200 is the collected
#                size and names the plain checkpoint, another size adds _px<N> to its name
#   US101, LANKERSHIM   folders of CommonRoad NGSIM scenario files (USA_US101-*_T-1.xml,
#                USA_Lanker-*_T-1.xml) to collect from, or
#   US101_DATA, LANKERSHIM_DATA   datasets already collected from them (`riskmap collect
#                --from-commonroad`), for a machine without commonroad-io; a family with
#                neither is skipped
#   RISKMAP      the riskmap command (default .venv/bin/riskmap)
# Budget at SCALE=full (what the shipped checkpoints' notes quote): 400 highway-v0 and 800
# intersection-v0 episodes collected on the cores, then as many epochs of batch 64 as fit
# before the deadline (at most 60 for the recorded families, whose few hundred windows would
# otherwise keep cores from the simulated ones). Half the windows of every epoch are drawn
# afresh (the perturbed-ego augmentation), so the cores, not the GPU, set the pace: each run
# gets sample workers in proportion to its windows.
set -euo pipefail
: "${OUT:?set OUT to the folder to write}"
SCALE=${SCALE:-full}
RISKMAP=${RISKMAP:-.venv/bin/riskmap}
RASTERS=${RASTERS:-200 100}
CORES=$(nproc)
START=$(date +%s)
case "$SCALE" in
  full) HIGHWAY_EPISODES=400; INTER_EPISODES=800; EPOCHS=200; RECORDED_EPOCHS=60; BATCH=64
        DEVICE=auto; RES=50; DEADLINE_S=${DEADLINE_S:-540}; LIMIT=() ;;
  tiny) HIGHWAY_EPISODES=3; INTER_EPISODES=3; EPOCHS=1; RECORDED_EPOCHS=1; BATCH=4; DEVICE=cpu
        RES=25; DEADLINE_S=${DEADLINE_S:-0}; LIMIT=(--max-windows 8) ;;
  *) echo "SCALE must be full or tiny, got '$SCALE'" >&2; exit 2 ;;
esac
case "$DEADLINE_S" in ''|*[!0-9]*) echo "DEADLINE_S must be whole seconds (0: none), got '$DEADLINE_S'" >&2; exit 2 ;; esac
for px in $RASTERS; do
  case "$px" in ''|*[!0-9]*) echo "RASTERS must be pixel counts such as '200 100', got '$RASTERS'" >&2; exit 2 ;; esac
done
mkdir -p "$OUT/data" "$OUT/runs" "$OUT/checkpoints"
log() { echo "[$(date +%H:%M:%S) +$(( $(date +%s) - START ))s] $*"; }
# sample workers of one training run with `share` sixteenths of the cores (none on a small machine,
# where the network's threads use every core)
workers() { local n=$(( CORES * $1 / 16 )); if [ "$CORES" -le 8 ]; then n=0; elif [ "$n" -lt 1 ]; then n=1; fi; echo "$n"; }

# Run "$@" until the deadline (exit 124 there, as timeout(1)); runs without one when DEADLINE_S=0.
until_deadline() {
  if [ "$DEADLINE_S" -eq 0 ]; then "$@"; return; fi
  local left=$(( START + DEADLINE_S - $(date +%s) ))
  if [ "$left" -le 5 ]; then return 124; fi
  timeout --signal=TERM --kill-after=20 "$left" "$@"
}

checkpoint_name() { if [ "$2" = 200 ]; then echo "$1"; else echo "${1}_px$2"; fi; }

# name  data  init-checkpoint  raster-px  workers  epochs  extra training flags
train_family() {
  local name=$1 data=$2 init=$3 px=$4 workers=$5 epochs=$6; shift 6
  local run="$OUT/runs/$name" status=0
  log "train $name (raster ${px} px)"
  until_deadline "$RISKMAP" train --planner spacetime --data "$data" --out "$run" --epochs "$epochs" \
      --batch-size "$BATCH" --lr 3e-4 --seed 0 --device "$DEVICE" --resolution "$RES" \
      --raster-px "$px" --workers "$workers" --init-checkpoint "$init" "${LIMIT[@]}" --resume \
      --quiet "$@" > "$OUT/runs/$name.out" 2>&1 || status=$?
  if [ ! -f "$run/best.safetensors" ]; then
    log "$name: no finished epoch (exit $status); see $OUT/runs/$name.out"; return 0
  fi
  [ "$status" -eq 0 ] || log "$name stopped at the deadline (exit $status); keeping its best epoch"
  for ext in safetensors json; do cp "$run/best.$ext" "$OUT/checkpoints/$name.$ext"; done
  cp "$run/log.csv" "$OUT/checkpoints/$name.log.csv"
}

init_for() {   # the spatial checkpoint a family starts from (at the tiny scale: a fresh tiny one)
  local spatial=$1 data=$2
  if [ "$SCALE" = full ]; then echo "checkpoints/$spatial"; return; fi
  "$RISKMAP" train --data "$data" --out "$OUT/runs/spatial_$spatial" --epochs 1 --batch-size 4 \
      --resolution "$RES" --device cpu --max-windows 8 --seed 0 --resume --quiet >/dev/null
  echo "$OUT/runs/spatial_$spatial/best"
}

recorded_data() {   # family  xml-folder  collected-dataset: the dataset to train on, or nothing
  local family=$1 xml=$2 collected=$3
  if [ -n "$collected" ]; then echo "$collected"; return; fi
  if [ -n "$xml" ]; then
    "$RISKMAP" collect --from-commonroad "$xml" --out "$OUT/data/$family" --resume --quiet >&2
    echo "$OUT/data/$family"
  fi
}

# 1. the recorded families (small: hundreds of windows) train while the simulated ones collect
US101_SET=$(recorded_data us101 "${US101:-}" "${US101_DATA:-}")
LANKERSHIM_SET=$(recorded_data lankershim "${LANKERSHIM:-}" "${LANKERSHIM_DATA:-}")
[ -z "$US101_SET" ] || US101_INIT=$(init_for riskmap_us101 "$US101_SET")
[ -z "$LANKERSHIM_SET" ] || LANKERSHIM_INIT=$(init_for riskmap_lankershim "$LANKERSHIM_SET")
pids=()
for px in $RASTERS; do
  if [ -n "$US101_SET" ]; then
    train_family "$(checkpoint_name riskmap_st_us101 "$px")" "$US101_SET" "$US101_INIT" "$px" \
        "$(workers 1)" "$RECORDED_EPOCHS" --val-groups 15,16,17,18 & pids+=($!)
  fi
  if [ -n "$LANKERSHIM_SET" ]; then
    train_family "$(checkpoint_name riskmap_st_lankershim "$px")" "$LANKERSHIM_SET" \
        "$LANKERSHIM_INIT" "$px" "$(workers 1)" "$RECORDED_EPOCHS" --predict-s 3 \
        --val-groups "USA_Lanker-2_1+2+3+4+16+19+21,USA_Lanker-2_15+23" & pids+=($!)
  fi
done

log "collect highway-v0 ($HIGHWAY_EPISODES episodes) and intersection-v0 ($INTER_EPISODES) on $CORES cores"
HALF=$(( CORES > 3 ? (CORES - 2) / 2 : 1 ))
"$RISKMAP" collect --env highway-v0 --episodes "$HIGHWAY_EPISODES" --seed 1000 --out "$OUT/data/highway" \
    --workers "$HALF" --resume --quiet & collect_highway=$!
"$RISKMAP" collect --env intersection-v0 --episodes "$INTER_EPISODES" --seed 1000 \
    --out "$OUT/data/intersection" --workers "$HALF" --resume --quiet & collect_inter=$!
wait "$collect_highway" "$collect_inter"
log "collected"

# 2. the simulated families, every raster size at once
HIGHWAY_INIT=$(init_for riskmap_highway "$OUT/data/highway")
if [ "$SCALE" = full ]; then PREDICT=(--predict-s 3); INTER=riskmap_intersection_yielding; else PREDICT=(); INTER=riskmap_intersection; fi
INTER_INIT=$(init_for "$INTER" "$OUT/data/intersection")
for px in $RASTERS; do
  train_family "$(checkpoint_name riskmap_st_highway "$px")" "$OUT/data/highway" "$HIGHWAY_INIT" "$px" \
      "$(workers 4)" "$EPOCHS" & pids+=($!)
  train_family "$(checkpoint_name riskmap_st_intersection "$px")" "$OUT/data/intersection" "$INTER_INIT" "$px" \
      "$(workers 3)" "$EPOCHS" "${PREDICT[@]}" & pids+=($!)
done
wait "${pids[@]}"

log "done: $OUT/checkpoints (epochs finished, best epoch, its validation ADE)"
for f in "$OUT"/checkpoints/*.log.csv; do
  python3 - "$f" <<'EOF'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
best = min(rows, key=lambda r: float(r["val_ade_m"]))
print(f"{sys.argv[1].split('/')[-1][:-8]:34s} epochs {len(rows):3d}  best {best['epoch']:>3s}  "
      f"val ADE {float(best['val_ade_m']):.2f} m  {sum(float(r['seconds']) for r in rows):.0f} s")
EOF
done
