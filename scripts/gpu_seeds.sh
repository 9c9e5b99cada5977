#!/usr/bin/env bash
# Several seeds of one recipe at the GPU shape (4,096 environments, batch 256 x 32), trained side
# by side on one GPU, each in its own process with a fifth of the GPU's memory (docs/TRAINING.md,
# "On a GPU"). What lands in OUT is small: per run an archive OUT/RECIPE-sSEED.tgz of its
# config.json, metrics.jsonl and every checkpoint's params with their step.json (no optimizer or
# resume state), enough for eval.py, export and `RUN/best` once unpacked (tar xzf ... -C runs/),
# and its console in OUT/train_sSEED.txt.
#
#   bash scripts/gpu_seeds.sh OUT RECIPE SECONDS SEED [SEED ...]
#   RESUME=1 bash scripts/gpu_seeds.sh ...      # continue runs a time limit stopped, on the same machine
#   GPU_CHECK_QUICK=1 bash scripts/gpu_seeds.sh /tmp/seeds velocity 300 1 2   # tiny sizes, on a CPU
#
# Packages: as scripts/gpu_check.sh, wheels in .whl/ installed to /tmp/site first.
set -uo pipefail
cd "$(dirname "$0")/.."
if [ $# -lt 4 ]; then
  echo "usage: bash scripts/gpu_seeds.sh OUT RECIPE SECONDS SEED [SEED ...]" >&2
  exit 2
fi
OUT=$1 RECIPE=$2 LIMIT=$3
shift 3
mkdir -p "$OUT"
PY=${PYTHON:-python3}
if [ "${GPU_CHECK_QUICK:-0}" = 1 ]; then
  SHAPE=(--num_envs 16 --batch_size 8 --num_minibatches 4 --num_timesteps 16384 --num_evals 2
         --num_eval_envs 4 --episode_length 50 --cpu_devices 1)
else
  SHAPE=(--num_envs 4096 --batch_size 256 --num_minibatches 32 --num_timesteps 30000000 --num_evals 15)
fi
RESUME_FLAG=()
[ "${RESUME:-0}" = 1 ] && RESUME_FLAG=(--resume)

if ls .whl/*.whl >/dev/null 2>&1; then
  "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    && export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
# JAX takes 75% of a GPU's memory per process by default: four processes would not start.
export XLA_PYTHON_CLIENT_MEM_FRACTION=${XLA_PYTHON_CLIENT_MEM_FRACTION:-0.2}
start=$(date +%s)
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv > "$OUT/facts.txt" 2>&1 || true

for seed in "$@"; do
  run=/tmp/gpu_seeds/$RECIPE-s$seed
  mkdir -p "$(dirname "$run")"
  timeout "$LIMIT" "$PY" train.py --recipe "$RECIPE" --seed "$seed" --run_dir "$run" "${SHAPE[@]}" \
    ${RESUME_FLAG[@]+"${RESUME_FLAG[@]}"} >> "$OUT/train_s$seed.txt" 2>&1 &
done
wait
echo "all runs ended $(( $(date +%s) - start )) s after the start" >> "$OUT/facts.txt"

for seed in "$@"; do
  run=/tmp/gpu_seeds/$RECIPE-s$seed dest=$OUT/$RECIPE-s$seed
  mkdir -p "$dest/checkpoints"
  cp "$run/config.json" "$run/metrics.jsonl" "$dest/" 2>/dev/null
  for ckpt in "$run"/checkpoints/*/; do
    [ -f "$ckpt/step.json" ] || continue
    mkdir -p "$dest/checkpoints/$(basename "$ckpt")"
    cp -r "$ckpt/params" "$ckpt/step.json" "$dest/checkpoints/$(basename "$ckpt")/"
  done
done
# The optimizer's and resume state's files stay behind, so their checksums go too: the params'
# checksum stays and is checked when they load.
"$PY" - "$OUT" <<'EOF'
import json, pathlib, sys
for path in pathlib.Path(sys.argv[1]).glob("*/checkpoints/*/step.json"):
    meta = json.loads(path.read_text())
    for key in ("optimizer_sha256", "resume", "resume_sha256"):
        meta.pop(key, None)
    path.write_text(json.dumps(meta))
EOF
# One archive per run: a few files to copy off the machine, not a few hundred in deep folders.
for seed in "$@"; do
  tar czf "$OUT/$RECIPE-s$seed.tgz" -C "$OUT" "$RECIPE-s$seed" && rm -r "${OUT:?}/$RECIPE-s$seed"
done
du -sh "$OUT"/*.tgz >> "$OUT/facts.txt"
