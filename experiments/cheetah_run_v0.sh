#!/usr/bin/env bash
# Cheetah-Run-v0 (torso length): ZeUS against its baselines, same data and update budget.
# Each run is the record -> retrain loop from bags (1,500 random steps, then 4 rounds of 2,000
# policy steps with exploration noise; 2,000 updates per round = 10,000 updates), followed by
# in-process evaluation on the train and extrapolation splits. Finished runs are skipped, so the
# script resumes where it stopped.  Usage: bash experiments/cheetah_run_v0.sh [OUT] [SEEDS...]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
OUT=${1:-runs/exp/cheetah_run_v0}
shift || true
SEEDS=${*:-0 1 2}
METHODS=${METHODS:-zeus zeus_no_context_loss no_context}
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
for seed in $SEEDS; do
  for method in $METHODS; do
    run="$OUT/${method}_s${seed}"
    if [ ! -f "$run/run/final.pt" ] || [ ! -f "$run/.done_train" ]; then
      rm -rf "$run"; mkdir -p "$OUT"
      start=$(date +%s)
      zeus loop --task Cheetah-Run-v0 --config params/train/state_cpu.yaml --method "$method" \
        --seed "$seed" --out "$run" --rounds 5 --random-steps 1500 --steps 2000 \
        --updates 2000 --noise 0.2 --no-eval --no-progress > "$run.train.log" 2>&1
      echo $(( $(date +%s) - start )) > "$run/.done_train"
    fi
    for split in train extrapolation; do
      if [ ! -f "$run/eval_$split/.done" ]; then
        start=$(date +%s)
        zeus eval --checkpoint "$run/run/final.pt" --task Cheetah-Run-v0 --split "$split" \
          --episodes 1 --switch-episodes 1 --probe-steps 0 --seed 100 \
          --out "$run/eval_$split" --no-progress > "$run.eval_$split.log" 2>&1
        echo $(( $(date +%s) - start )) > "$run/eval_$split/.done"
      fi
    done
    echo "done: $run (train $(cat "$run/.done_train") s)"
  done
done
