#!/usr/bin/env bash
# Run the lines of a queue file, JOBS at a time (default 2), each through run_one.sh:
#   CONFIG TASK METHOD SEED OUT_ROOT      (one run per line; '#' starts a comment)
# Finished runs are skipped and unfinished ones resume, so rerunning the same queue resumes it.
#   usage: [JOBS=2] [EVAL=0] nice bash experiments/run_queue.sh experiments/queues/issue10.txt
set -euo pipefail
cd "$(dirname "$0")/.."
grep -v '^\s*#' "$1" | grep -v '^\s*$' | xargs -P "${JOBS:-2}" -L 1 sh -c \
  'CONFIG="$0" bash experiments/run_one.sh "$1" "$2" "$3" "$4"'
