#!/usr/bin/env bash
# The 60-minute wall budget of route (b): zeus loop under timeout (SIGTERM saves the checkpoint).
cd /work/wt_pixrl
source scripts/env.sh
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 MUJOCO_GL=egl PYTHONUNBUFFERED=1
start=$(date +%s)
echo "$start START" > runs/pixels_rl_cpu/s0.log
nice -n 10 timeout -s TERM -k 180 3600 zeus loop --task Cheetah-Bias-v0 \
  --config params/train/pixels_cpu.yaml --out runs/pixels_rl_cpu/s0 --rounds 12 \
  --random-steps 1500 --steps 500 --updates 400 --seed 0 --no-progress 2>&1 | \
  while IFS= read -r line; do echo "$(date +%s) $line"; done >> runs/pixels_rl_cpu/s0.log
echo "$(date +%s) END rc=${PIPESTATUS[0]}" >> runs/pixels_rl_cpu/s0.log
