#!/usr/bin/env bash
# One run of the comparison: the record -> retrain loop from bags for one (task, method, seed),
# then in-process evaluation on every split the task's preset defines. Same data and update
# budget for every method: 1,500 random steps, then ROUNDS-1 rounds of 2,000 policy steps with
# exploration noise 0.2, 2,000 updates per round (ROUNDS=5: 10,000 updates). A longer run
# (ROUNDS > 5, folder <task>_<updates>k) starts from a copy of the longest finished shorter run
# of the same (task, method, seed) and continues it with `zeus loop --resume`, which is the same
# as running all rounds at once (a 30k run continues the 20k one, which continued the 10k one).
# Finished parts are skipped, so rerunning resumes; a lock folder stops two copies of a run.
# What is finished is recorded in <run>/state.json (zeus_ros/offline/runs.py);
# runs finished before it, marked by .done_train / eval_<split>/.done files, count as finished.
# CONFIG (default params/train/state_cpu.yaml) picks the training config (a variant goes in its
# own OUT_ROOT); EVAL=0 skips the evaluation (run `zeus eval` over the checkpoints later).
#   usage: [ROUNDS=10] [CONFIG=...] [EVAL=0] [SCHEDULE=...] bash experiments/run_one.sh TASK METHOD SEED [OUT_ROOT]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
TASK=$1 METHOD=$2 SEED=$3
ROOT=${4:-runs/exp}
ROUNDS=${ROUNDS:-5}
CONFIG=${CONFIG:-params/train/state_cpu.yaml}
BASE="$ROOT/$(echo "$TASK" | tr 'A-Z-' 'a-z_')"
OUT=$BASE
if [ "$ROUNDS" != 5 ]; then OUT="${BASE}_$((ROUNDS * 2))k"; fi
run="$OUT/${METHOD}_s${SEED}"
state() { python -m zeus_ros.cli.run_state "$@"; }
# finished RUN [SPLIT...]: 0 finished, 1 not yet; an unreadable state.json ends the script (its
# one-line error says what to do)
finished() { local rc=0; state done "$@" || rc=$?; [ "$rc" -le 1 ] || exit "$rc"; return "$rc"; }
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
# Collection switches the context every 100 steps (5 times per 500-step episode); the
# reward-varying family has 40-step episodes, so it switches every 20 steps there (`zeus eval`
# then switches every 10 steps, a quarter episode).
# SCHEDULE overrides it for every method alike (a protocol of its own goes in its own OUT_ROOT),
# e.g. SCHEDULE=switch:train:every_episodes=1 keeps one context per episode.
collect_every=100
if [ "$TASK" = Cheetah-Run-v1 ]; then collect_every=20; fi
SCHEDULE=${SCHEDULE:-switch:train:every=$collect_every}
mkdir -p "$OUT"
if ! mkdir "$run.lock" 2>/dev/null; then echo "skip: $run is running elsewhere"; exit 0; fi
trap 'rmdir "$run.lock"' EXIT
# the longest finished run of this (task, method, seed) with fewer rounds, if any
base_run=""
for ((r = ROUNDS - 1; r >= 5; r--)); do
  if [ "$r" = 5 ]; then candidate="$BASE/${METHOD}_s${SEED}"
  else candidate="${BASE}_$((r * 2))k/${METHOD}_s${SEED}"; fi
  if [ -f "$candidate/run/final.pt" ] && finished "$candidate"; then base_run=$candidate; break; fi
done
if [ ! -f "$run/run/final.pt" ] || ! finished "$run"; then
  resume=()
  if [ -n "$base_run" ] && [ ! -d "$run/run" ]; then
    mkdir -p "$run" && cp -r "$base_run/bags" "$base_run/run" "$run/"
    earlier=$(state seconds "$base_run")
    if [ -n "$earlier" ]; then state mark-continued "$run" "$earlier"; fi
  fi
  if [ -d "$run/run" ]; then resume=(--resume); else rm -rf "$run"; fi
  start=$(date +%s)
  zeus loop --task "$TASK" --config "$CONFIG" --method "$METHOD" \
    --seed "$SEED" --out "$run" --rounds "$ROUNDS" --random-steps 1500 --steps 2000 \
    --updates 2000 --noise 0.2 --schedule "$SCHEDULE" \
    "${resume[@]}" --no-eval --no-progress >> "$run.train.log" 2>&1
  state mark-trained "$run" $(( $(date +%s) - start ))
fi
if [ "${EVAL:-1}" = 0 ]; then echo "done: $run (train $(state seconds "$run") s)"; exit 0; fi
for split in $(python -c "from sim_bridge.families import family; print(' '.join(family('$TASK').presets))"); do
  if ! finished "$run" "$split"; then
    start=$(date +%s)
    zeus eval --checkpoint "$run/run/final.pt" --task "$TASK" --split "$split" \
      --switch-episodes 1 --probe-steps 0 \
      --seed 100 --out "$run/eval_$split" --no-progress > "$run.eval_$split.log" 2>&1
    state mark-evaluated "$run" "$split" $(( $(date +%s) - start ))
  fi
done
echo "done: $run (train $(state seconds "$run") s)"
