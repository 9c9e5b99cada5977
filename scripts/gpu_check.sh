#!/usr/bin/env bash
# Everything a GPU machine is asked, in one go (docs/TRAINING.md, "On a GPU"): the machine's
# facts, a short training of the fast preset at GPU batch sizes, the environment benchmark at 1,024
# to 8,192 environments on flat ground and on mixed and hard terrain, a short training of the
# velocity recipe, and MJX's Warp implementation's physics speed where it imports. Each part has
# its own time limit and a failed part does not stop the next; every figure lands in OUT as a few
# flat text files.
#
#   bash scripts/gpu_check.sh [OUT]        # OUT: default runs/gpu_check
#   GPU_CHECK_QUICK=1 bash scripts/gpu_check.sh /tmp/gpu_check   # tiny sizes: checks the script on a CPU
#
# Packages: the machine's own jax is used. Packages it lacks travel as wheels in .whl/ and are
# installed to /tmp/site first; scripts/gpu_wheels.txt lists them and how to fetch them.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-runs/gpu_check}
mkdir -p "$OUT"
PY=${PYTHON:-python3}
QUICK=${GPU_CHECK_QUICK:-0}
if [ "$QUICK" = 1 ]; then
  BATCHES="8 16"; STEPS=5; ENVS=16; BATCH=8; MINIBATCHES=4; TRAIN_STEPS=8192; LIMIT=600
  # One CPU device: XLA:CPU in jax 0.11 (a GPU image's) crashes compiling PPO's pmap over two.
  EXTRA=(--num_evals 2 --num_eval_envs 4 --episode_length 50 --cpu_devices 1)
else
  # Limits sized so that every part fits in 8 minutes (a GPU machine booked for 15 minutes, its
  # start included): the fast preset 150 s, the benchmark 170 s, the velocity recipe
  # 120 s, Warp 45 s.
  BATCHES="1024 4096 8192"; STEPS=100; ENVS=4096; BATCH=256; MINIBATCHES=32; TRAIN_STEPS=30000000; LIMIT=150
  EXTRA=(--num_evals 15)
fi

if ls .whl/*.whl >/dev/null 2>&1; then
  "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    && export PYTHONPATH=/tmp/site
fi
# MUJOCO_GL is left to hexa_mjx (EGL or OSMesa where the library is there): nothing here renders,
# and forcing EGL on an image without libEGL stops MuJoCo's import.
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
start=$(date +%s)
stamp() { echo "== $1 ($(( $(date +%s) - start )) s after the start)"; }

stamp "facts" | tee "$OUT/facts.txt"
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>&1 || true
  "$PY" -c "
import importlib.metadata as m, jax
for p in ('jax', 'jaxlib', 'mujoco', 'mujoco-mjx', 'brax', 'flax', 'optax', 'orbax-checkpoint'):
    try: print(p, m.version(p))
    except m.PackageNotFoundError: print(p, 'missing')
print('devices', jax.devices())" 2>&1; } | tee -a "$OUT/facts.txt"

train() {  # NAME SECONDS ARGS...: a short training run, its console and metrics copied into OUT
  local name=$1 limit=$2; shift 2
  stamp "training: $name" | tee "$OUT/train_$name.txt"
  rm -rf "/tmp/gpu_check_$name"
  timeout "$limit" "$PY" train.py --run_dir "/tmp/gpu_check_$name" --num_envs "$ENVS" --batch_size "$BATCH" \
    --num_minibatches "$MINIBATCHES" --num_timesteps "$TRAIN_STEPS" ${EXTRA[@]+"${EXTRA[@]}"} "$@" 2>&1 | tee -a "$OUT/train_$name.txt"
  cp "/tmp/gpu_check_$name/metrics.jsonl" "$OUT/metrics_$name.jsonl" 2>/dev/null || true
}
train fast "$LIMIT" --recipe fast  # first: the figure a user asks first, how soon a policy walks
stamp "benchmark: flat, mixed and hard terrain" | tee "$OUT/benchmark.txt"
# shellcheck disable=SC2086  # BATCHES is a list
timeout $((LIMIT + 20)) "$PY" -m hexa_mjx.studies.benchmark --batches $BATCHES --steps $STEPS --repeats 3 \
  --compare_terrain mixed hard 2>&1 | tee -a "$OUT/benchmark.txt"
train velocity $((LIMIT * 4 / 5)) --recipe velocity

stamp "MJX's Warp implementation: physics only" | tee "$OUT/warp.txt"
timeout $((LIMIT * 3 / 10)) "$PY" - "$BATCHES" "$STEPS" <<'EOF' 2>&1 | tee -a "$OUT/warp.txt"
# Physics steps/s of mjx.step under the JAX and the Warp implementations: hexa_mjx reads contacts
# from the JAX implementation's data, so Warp is timed on the physics alone.
import importlib.util, sys, time
if importlib.util.find_spec("warp") is None:  # don't spend the machine's minutes on the JAX half alone
    sys.exit("warp: not run: warp-lang is not installed (its wheel is about 150 MB)")
import jax, mujoco
from mujoco import mjx
from hexa_mjx.robot import constants
model = mujoco.MjModel.from_xml_path(str(constants.MODEL_XML))
for impl in ("jax", "warp"):
    try:
        m = mjx.put_model(model, impl=impl)
        for batch in map(int, sys.argv[1].split()):
            data = jax.vmap(lambda _: mjx.make_data(m))(jax.numpy.arange(batch))
            run = jax.jit(lambda d: jax.lax.fori_loop(0, int(sys.argv[2]), lambda _, x: jax.vmap(mjx.step, (None, 0))(m, x), d))
            jax.block_until_ready(run(data))
            t = time.perf_counter(); jax.block_until_ready(run(data)); t = time.perf_counter() - t
            print(f"{impl}: batch {batch}: {batch * int(sys.argv[2]) / t:,.0f} physics steps/s")
    except Exception as e:  # noqa: BLE001 - reported, not fatal: Warp is optional
        print(f"{impl}: not run: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}")
EOF
stamp "done" | tee -a "$OUT/facts.txt"
