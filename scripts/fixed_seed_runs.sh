#!/usr/bin/env bash
# Three short fixed-seed training runs that touch every episode event (start noise, pushes,
# latency, leg failure, observation noise, curriculum, terrain, randomized physics), for checking
# that a change keeps training bit-identical:
#
#   cp scripts/fixed_seed_runs.sh /tmp/ && git checkout OLD && bash /tmp/fixed_seed_runs.sh /tmp/before
#   git checkout main && bash scripts/fixed_seed_runs.sh /tmp/after
#   .venv/bin/python scripts/compare_rows.py /tmp/before /tmp/after
#
# Run it from the repository root. About 8 minutes on a 2-core CPU (three cold compiles).
set -euo pipefail
OUT=${1:?usage: fixed_seed_runs.sh OUT_FOLDER}
PY=${PY:-.venv/bin/python}
TINY="--num_envs 16 --batch_size 16 --num_minibatches 2 --unroll_length 8 --num_timesteps 1024 --num_evals 2
      --num_eval_envs 4 --episode_length 40 --hidden 16 16 --update_epochs 2 --no_compile_cache --cpu_devices 1
      --no_progress"
mkdir -p "$OUT"
$PY train.py $TINY --seed 3 --run_dir "$OUT/goal" > "$OUT/goal.log" 2>&1
$PY train.py $TINY --seed 4 --task navigate --push_speed 0.5 --push_interval 0.1 --action_latency 0.5 \
    --leg_failure random --obs_noise 1 --start_joint_noise 0.1 --curriculum_levels 3 --run_dir "$OUT/nav" > "$OUT/nav.log" 2>&1
$PY train.py $TINY --seed 5 --task navigate --terrain mixed --failure_mode locked --leg_failure random \
    --leg_failure_rate 1 --randomize --run_dir "$OUT/terrain" > "$OUT/terrain.log" 2>&1
echo "runs in $OUT: goal nav terrain"
