#!/bin/bash
# Warm start of train.py, side by side (docs/RESULTS.md, "Warm start"): the fast preset as it is (A)
# and with --no_progress --no_record_optimizer (B; once the only setting whose training
# program the cache kept), cache emptied first; each console line is stamped with the seconds since
# that run's launch.  Usage: bash scripts/warm_start.sh [cache folder]
set -o pipefail
cd "$(dirname "$0")/.."
export JAX_COMPILATION_CACHE_DIR=${1:-/tmp/warmcache}
rm -rf "$JAX_COMPILATION_CACHE_DIR"
PY=${PYTHON:-.venv/bin/python}
run() {
  local name=$1; shift
  rm -rf "/tmp/warm-$name"
  local start; start=$(date +%s.%N)
  "$PY" -u train.py --preset fast --num_timesteps 16384 --num_evals 2 --run_dir "/tmp/warm-$name" "$@" 2>&1 |
    while IFS= read -r line; do
      printf '%s %6.1f %s\n' "$name" "$(awk "BEGIN {print $(date +%s.%N) - $start}")" "$line"
    done
}
run A1; run A2; run B1 --no_progress --no_record_optimizer; run B2 --no_progress --no_record_optimizer
run A3; run B3 --no_progress --no_record_optimizer
ls "$JAX_COMPILATION_CACHE_DIR"
