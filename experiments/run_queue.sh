#!/usr/bin/env bash
# Run the lines of a queue file through run_one.sh, at most JOBS training runs at a time
# (default 2: one per core), counting every run_one.sh on the machine:
#   CONFIG TASK METHOD SEED OUT_ROOT [ROUNDS] [SCHEDULE]   (one run per line; '#' starts a
#   comment; ROUNDS and SCHEDULE as in run_one.sh, default 5 = 10k updates and its schedule)
# The file is read again before each start, so lines can be added or reordered while it runs;
# trained runs (their state.json, or the .done_train marker of runs from before it) and runs
# locked by another copy are skipped, unfinished ones resume.
#   usage: [JOBS=2] [EVAL=0] nice bash experiments/run_queue.sh experiments/queues/issue10.txt
set -uo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
QUEUE=$1 JOBS=${JOBS:-2}
next_line() {
  grep -v '^\s*#' "$QUEUE" | grep -v '^\s*$' | while read -r config task method seed root rounds schedule; do
    rounds=${rounds:-5}
    folder="$root/$(echo "$task" | tr 'A-Z-' 'a-z_')"
    if [ "$rounds" != 5 ]; then folder="${folder}_$((rounds * 2))k"; fi
    run="$folder/${method}_s${seed}"
    [ -d "$run.lock" ] && continue
    python -m zeus_ros.cli.run_state done "$run" < /dev/null
    case $? in
      0) ;;  # trained
      1) echo "$config $task $method $seed $root $rounds $schedule"; break ;;
      *) echo "queue: skip $run (its state is unreadable, see above)" >&2 ;;
    esac
  done
}
while true; do
  # run_one.sh, not `zeus loop`: a run resuming from a shorter one prepares for a while first
  while [ "$(pgrep -fc 'experiments/run_one.sh')" -ge "$JOBS" ]; do sleep 5; done
  line=$(next_line)
  if [ -z "$line" ]; then wait; echo "queue: nothing left in $QUEUE"; exit 0; fi
  read -r config task method seed root rounds schedule <<< "$line"
  echo "queue: start $task $method seed $seed, $rounds rounds ($config -> $root${schedule:+, $schedule})"
  ROUNDS="$rounds" CONFIG="$config" SCHEDULE="$schedule" \
    bash experiments/run_one.sh "$task" "$method" "$seed" "$root" &
  sleep 8  # let it take its lock and start before counting again
done
