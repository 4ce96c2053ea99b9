#!/usr/bin/env bash
# Every run of the comparison, JOBS at a time (default 2: one per core of the dev machine).
# TASKS, METHODS and SEEDS choose the grid; runs already finished are skipped, so the command
# resumes after an interruption.
#   TASKS="Walker-Walk-v0" METHODS="zeus no_context" bash experiments/run_all.sh [OUT_ROOT]
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-runs/exp}
TASKS=${TASKS:-Cheetah-Run-v0 Walker-Walk-v0 Walker-Walk-v1 Finger-Spin-v0 Cheetah-Run-v1}
METHODS=${METHODS:-zeus zeus_no_context_loss no_context}
SEEDS=${SEEDS:-0 1 2}
for task in $TASKS; do for seed in $SEEDS; do for method in $METHODS; do
  echo "$task $method $seed"
done; done; done | xargs -P "${JOBS:-2}" -L 1 sh -c 'bash experiments/run_one.sh "$0" "$1" "$2" '"$ROOT"
