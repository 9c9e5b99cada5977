#!/bin/bash
# Warm start of two checkouts side by side (docs/RESULTS.md, "A warm start without tracing"): the
# fast preset for 16,384 steps, each checkout with its own compile cache, emptied first; one run
# each to fill it, then RUNS warm runs each, in turns. Every console line is stamped with the
# seconds since that run's launch.  Usage: bash scripts/warm_start_checkouts.sh DIR_A DIR_B [RUNS]
set -o pipefail
A=$(cd "$1" && pwd); B=$(cd "$2" && pwd); RUNS=${3:-3}
PY=${PYTHON:-$(cd "$(dirname "$0")/.." && pwd)/.venv/bin/python}
run() {  # run NAME DIR: one stamped run of DIR's train.py
  local name=$1 dir=$2 start
  rm -rf "/tmp/warmck-$name"
  start=$(date +%s.%N)
  (cd "$dir" && JAX_COMPILATION_CACHE_DIR="/tmp/warmck-cache-$(basename "$dir")" "$PY" -u train.py --recipe fast \
      --num_timesteps 16384 --num_evals 2 --run_dir "/tmp/warmck-$name" 2>&1) |
    while IFS= read -r line; do
      printf '%s %6.1f %s\n' "$name" "$(awk "BEGIN {print $(date +%s.%N) - $start}")" "$line"
    done
}
rm -rf "/tmp/warmck-cache-$(basename "$A")" "/tmp/warmck-cache-$(basename "$B")"
run A0 "$A"; run B0 "$B"
for i in $(seq 1 "$RUNS"); do run "A$i" "$A"; run "B$i" "$B"; done
