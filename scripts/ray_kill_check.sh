#!/usr/bin/env bash
# A study grid on a local Ray instance, with one Ray worker killed (kill -9) in the middle of a run:
# Ray retries the task, the retry resumes from the run's last checkpoint, and the grid completes.
# Prints each run's evaluation steps (each must appear once), leftover tmp-* folders and the verdict.
#   bash scripts/ray_kill_check.sh [OUT] [TIMESTEPS]
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-runs/ray-kill-check}
STEPS=${2:-163840}
rm -rf "$OUT"
.venv/bin/python -m hexa_mjx.studies.experiments lr --seeds 1 --timesteps "$STEPS" --ray --run_cpus 1 --out "$OUT" \
  > "$OUT.log" 2>&1 &
GRID=$!
# Wait for a run that has written a checkpoint but not finished, then kill the worker training it.
while kill -0 $GRID 2>/dev/null; do
  if ls "$OUT"/lr/*/checkpoints/0* >/dev/null 2>&1; then
    VICTIM=$(pgrep -f "ray::train_in_worker" | head -1 || true)
    if [ -n "$VICTIM" ]; then
      echo "$(date +%T) kill -9 Ray worker $VICTIM (checkpoints so far: $(ls -d "$OUT"/lr/*/checkpoints/0* | wc -l))"
      kill -9 "$VICTIM"
      break
    fi
  fi
  sleep 2
done
wait $GRID
echo "grid exit code: $?"
.venv/bin/python - "$OUT" "$STEPS" <<'EOF'
import json, sys
from pathlib import Path
out, budget = Path(sys.argv[1]), int(sys.argv[2])
ok = True
for run in sorted((out / "lr").iterdir()):
    steps = [json.loads(line)["step"] for line in (run / "metrics.jsonl").read_text().splitlines()]
    ckpts = sorted(int(p.name) for p in (run / "checkpoints").iterdir() if p.name.isdigit())
    tmp = list((run / "checkpoints").glob("tmp-*"))
    good = len(steps) == len(set(steps)) and steps == sorted(steps) and steps[-1] >= budget and not tmp
    ok &= good
    print(f"{run.name}: evaluation steps {steps}; checkpoints {len(ckpts)}, last {ckpts[-1]:,}; tmp-* left {len(tmp)}")
print("every run finished, each evaluation row once, no tmp-* left" if ok else "FAILED")
EOF
grep -h "resuming" "$OUT.log" | sed 's/^/  log: /' || true
