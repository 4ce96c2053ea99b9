#!/usr/bin/env bash
# Every run of the comparison, as one `zeus sweep` (docs/sweep.md): TASKS x METHODS x SEEDS, each
# trial the protocol of run_one.sh (1,500 random steps, then 4 rounds of 2,000 policy steps with
# noise 0.2, 2,000 updates per round; every split evaluated), JOBS trials at a time (default 2:
# one per core of the dev machine) on a local loopback-only Ray, or on the cluster of RAY_ADDRESS.
# Finished trials are skipped, so the command resumes after an interruption.
#   TASKS="Walker-Walk-v0" METHODS="zeus no_context" bash experiments/run_all.sh [OUT_ROOT [FLAGS]]
# FLAGS go to zeus sweep as they are (e.g. --dry-run, --set alpha_psi=0.5,1.0).
# Longer runs continued from the 5-round ones (ROUNDS=10, folders <task>_20k): run_one.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
if [ "${ROUNDS:-5}" != 5 ]; then
  echo "run_all.sh: ROUNDS=$ROUNDS: continue runs with ROUNDS=$ROUNDS bash experiments/run_one.sh TASK METHOD SEED" >&2
  exit 2
fi
read -r -a tasks <<< "${TASKS:-Cheetah-Run-v0 Walker-Walk-v0 Walker-Walk-v1 Finger-Spin-v0 Cheetah-Run-v1}"
read -r -a methods <<< "${METHODS:-zeus zeus_no_context_loss no_context}"
seeds=$(echo "${SEEDS:-0 1 2}" | xargs | tr ' ' ,)
out=${1:-runs/exp}
shift || true
local_cpus=(--num-cpus "${JOBS:-2}")
if [ -n "${RAY_ADDRESS:-}" ]; then local_cpus=(); fi
exec zeus sweep --tasks "${tasks[@]}" --methods "${methods[@]}" --seeds "$seeds" \
  --config "${CONFIG:-params/train/state_cpu.yaml}" --out "$out" "${local_cpus[@]}" "$@"
